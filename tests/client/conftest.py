"""A live `skyhelm serve` (real subprocess, ephemeral port, simulated quad) for the client."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from skyhelm_client import State
from tests.serve_process import Served, skyhelm_serve

# Sim seconds per wall second: PX4's timeouts inside the sim scale with it.
SIM_SPEED = "8"


@pytest.fixture
def served(tmp_path: Path) -> Iterator[Served]:
    with skyhelm_serve(tmp_path, "--no-scene", "--sim-speed", SIM_SPEED) as served:
        yield served


def pilot_url(served: Served) -> str:
    """What `skyhelm serve` printed: the URL a script is given."""
    return f"{served.base_url}/?token={served.pilot_token}"


def ready(state: State) -> bool:
    """Position and home known: the vehicle may arm."""
    return state["global"] is not None and state["home"] is not None
