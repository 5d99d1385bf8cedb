"""The REST flight of docs/api.md (the same stages as tests/api/test_rest_flight.py) against
real PX4 v1.16 SITL, with `skyhelm serve --connect udpin:...` and default settings."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.px4.conftest import Px4Sitl
from tests.rest_flight import RestFlight
from tests.rest_flight_stages import STAGE_NAMES, run_stage
from tests.serve_process import Served

pytestmark = pytest.mark.px4


@pytest.fixture(scope="module")
def flight(px4: Px4Sitl, served_px4: Served) -> Iterator[RestFlight]:
    session = RestFlight(served_px4, vehicle_id=px4.sysid)
    yield session
    session.http.close()


@pytest.mark.parametrize("stage", STAGE_NAMES)
def test_px4_rest_flight(flight: RestFlight, stage: str) -> None:
    run_stage(flight, stage)
