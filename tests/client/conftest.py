"""A live `skyhelm serve` (real subprocess, ephemeral port, simulated quad) for the client."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.serve_process import Served, skyhelm_serve

# Sim seconds per wall second: PX4's timeouts inside the sim scale with it.
SIM_SPEED = "8"
# Real time's margin on PX4's disarm of a vehicle armed on the ground and not taken off
# (COM_DISARM_PRFLT 10 s is 1.25 s of wall time at 8x: a script that armed, then took off on a
# busy machine found its vehicle disarmed), set at the sim's start as PX4 SITL takes it.
SLOW_PREFLIGHT_DISARM = {"PX4_PARAM_COM_DISARM_PRFLT": str(10 * int(SIM_SPEED))}


@pytest.fixture
def served(tmp_path: Path) -> Iterator[Served]:
    with skyhelm_serve(
        tmp_path, "--no-scene", "--sim-speed", SIM_SPEED, env=SLOW_PREFLIGHT_DISARM
    ) as served:
        yield served


def pilot_url(served: Served) -> str:
    """What `skyhelm serve` printed: the URL a script is given."""
    return f"{served.base_url}/?token={served.pilot_token}"
