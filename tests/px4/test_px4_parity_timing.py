"""The sim keeps real PX4 v1.16 SITL's time and parameters: one quad flight (takeoff, offboard
move and loss, land, RTL) and one standard VTOL flight (front and back transition) flown the
same way on both by bench/parity_timing.py's ground station, every step within 30 % of PX4
(on each vehicle's own clock), and every parameter the sim's quad, VTOL and plane have equal
to PX4 SITL's for that airframe (system id and SYS_AUTOSTART aside)."""

from __future__ import annotations

import pytest

from bench import parity_timing as parity
from tests.px4.conftest import MODEL, Px4Sitl, find_sitl

pytestmark = pytest.mark.px4

# the sim flies faster than wall time here; every figure is on its own clock
SIM_SPEED = 3.0
# PX4 SITL's SIH model of each sim airframe
SIH_MODELS = {"quad": MODEL, "vtol": "sihsim_standard_vtol", "plane": "sihsim_airplane"}


@pytest.fixture(scope="module")
def sitl() -> Px4Sitl:
    return find_sitl()


@pytest.fixture(scope="module")
def flights(sitl: Px4Sitl) -> tuple[dict[str, float], dict[str, float]]:
    """(sim row, PX4 row): one quad flight each, each vehicle started fresh (PX4 clean)."""
    with parity.sim_vehicle("quad", SIM_SPEED) as gcs:
        sim_row = parity.fly_quad(gcs)
    with parity.px4_vehicle(sitl.sitl_dir, sitl.instance, MODEL) as gcs:
        px4_row = parity.fly_quad(gcs)
    return sim_row, px4_row


def test_every_flight_phase_within_30_percent_of_px4(
    flights: tuple[dict[str, float], dict[str, float]],
) -> None:
    sim_row, px4_row = flights
    rows = parity.compare(sim_row, px4_row)
    quad_rows = [r for r in rows if r["key"] in dict(parity.QUAD_ROWS)]
    out = [f"{r['step']}: sim {r['sim']:.2f}, PX4 {r['px4']:.2f}"
           for r in quad_rows if not r["within_30_pct"]]
    assert not out, "outside 30 % of PX4: " + "; ".join(out)


def test_vtol_transitions_within_30_percent_of_px4(sitl: Px4Sitl) -> None:
    with parity.sim_vehicle("vtol", SIM_SPEED) as gcs:
        sim_row = parity.fly_vtol(gcs)
    with parity.px4_vehicle(sitl.sitl_dir, sitl.instance, SIH_MODELS["vtol"]) as gcs:
        px4_row = parity.fly_vtol(gcs)
    rows = [r for r in parity.compare(sim_row, px4_row) if r["key"] in dict(parity.VTOL_ROWS)]
    assert len(rows) == 2
    out = [f"{r['step']}: sim {r['sim']:.2f}, PX4 {r['px4']:.2f}"
           for r in rows if not r["within_30_pct"]]
    assert not out, "outside 30 % of PX4: " + "; ".join(out)


@pytest.mark.parametrize("airframe", ["quad", "vtol", "plane"])
def test_every_sim_parameter_equals_px4_sitl(sitl: Px4Sitl, airframe: str) -> None:
    with parity.px4_vehicle(sitl.sitl_dir, sitl.instance, SIH_MODELS[airframe]) as gcs:
        parity.boot(gcs)
        theirs = parity.read_params(gcs)
    with parity.sim_vehicle(airframe, SIM_SPEED) as gcs:
        parity.boot(gcs)
        ours = parity.read_params(gcs)
    census = parity.census({airframe: ours}, {airframe: theirs})[airframe]
    assert census["shared"] == len(ours), f"the sim has parameters PX4 lacks: {census['sim_only']}"
    assert census["differ"] == {}
