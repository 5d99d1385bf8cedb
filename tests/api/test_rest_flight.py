"""The REST flight of docs/api.md on the built-in simulated quad, with `skyhelm serve`'s
default settings: one test per stage, in flying order (tests/rest_flight_stages.py).

The simulated quad flies at 3× real time (its PX4 timeouts scale with it) while the server's
leases, deadman and stream keep wall time, so the flight's ~50 s of climbing, flying and the
return home take a third of that; tests/px4 flies the same stages at real time on PX4 SITL."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.rest_flight import RestFlight
from tests.rest_flight_stages import STAGE_NAMES, run_stage
from tests.serve_process import skyhelm_serve

# Sim seconds per wall second (the browser tests fly at 2-3 too).
SIM_SPEED = "3"


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RestFlight]:
    # --no-scene: the 3D scene has nothing to do with control and costs CPU on a small machine.
    with skyhelm_serve(tmp_path_factory.mktemp("rest-flight"), "--no-scene",
                       "--sim-speed", SIM_SPEED) as served:
        session = RestFlight(served)
        yield session
        session.http.close()


@pytest.mark.parametrize("stage", STAGE_NAMES)
def test_rest_flight(flight: RestFlight, stage: str) -> None:
    run_stage(flight, stage)
