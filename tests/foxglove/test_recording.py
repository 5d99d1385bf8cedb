"""MCAP files: the one written beside the .tlog during a flight, and `skyhelm convert`'s
from that .tlog, read back with the mcap library: the same messages per MAVLink type."""

from __future__ import annotations

from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import pytest_asyncio
from mcap.reader import make_reader

from server.cli import main
from server.link.codec.tlog import iter_tlog
from tests.api.conftest import api_for, sim_cluster

from .counts import mcap_mavlink_counts, mcap_topics, tlog_counts
from .test_live import fly_offboard

pytestmark = pytest.mark.asyncio(loop_scope="module")


@dataclass
class Recording:
    tlog: Path
    mcap: Path


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def recording(tmp_path_factory: pytest.TempPathFactory) -> AsyncIterator[Recording]:
    log_dir = tmp_path_factory.mktemp("logs")
    async with sim_cluster("quad") as sim, api_for(sim, mcap=True, log_dir=log_dir) as api:
        await api.wait_ready()
        bridge = api.app.state.foxglove
        await fly_offboard(api)
        tlog = next(iter(api.app.state.api.registry.links)).tlog_path
    # the app has stopped: links, .tlog and MCAP file are closed
    assert tlog is not None
    assert bridge.mcap_paths == [tlog.with_suffix(".mcap")]
    yield Recording(tlog, tlog.with_suffix(".mcap"))


def _mcap(path: Path) -> tuple[dict[str, int], set[str]]:
    with path.open("rb") as file:
        counts = mcap_mavlink_counts(make_reader(file))
    with path.open("rb") as file:
        topics = mcap_topics(make_reader(file))
    return counts, topics


async def test_the_mcap_written_during_a_flight_has_the_tlogs_messages_per_type(
    recording: Recording,
) -> None:
    tlog = tlog_counts(iter_tlog(recording.tlog))
    counts, topics = _mcap(recording.mcap)
    assert tlog["SET_POSITION_TARGET_LOCAL_NED"] > 10  # the setpoints sent are in both
    assert counts == tlog
    assert {"/vehicle_1/location", "/vehicle_1/tf", "/vehicle_1/pose", "/vehicle_1/log",
            "/vehicle_1/state", "/vehicle_1/health"} <= topics


async def test_convert_writes_a_tlogs_messages_and_what_derives_from_them(
    recording: Recording, tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    target = tmp_path / "flight.mcap"
    assert main(["convert", str(recording.tlog), str(target)]) == 0
    tlog = tlog_counts(iter_tlog(recording.tlog))
    counts, topics = _mcap(target)
    assert counts == tlog
    assert {"/vehicle_1/location", "/vehicle_1/tf", "/vehicle_1/pose", "/vehicle_1/log",
            "/vehicle_1/sent/SET_POSITION_TARGET_LOCAL_NED"} <= topics
    assert f"{sum(tlog.values())} MAVLink messages" in capsys.readouterr().out


async def test_convert_keeps_an_existing_file_and_names_a_missing_one(
    recording: Recording, tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    existing = tmp_path / "kept.mcap"
    existing.write_bytes(b"mine")
    assert main(["convert", str(recording.tlog), str(existing)]) == 2
    assert existing.read_bytes() == b"mine"
    assert main(["convert", str(tmp_path / "none.tlog"), str(tmp_path / "x.mcap")]) == 2
    errors = capsys.readouterr().err
    assert "--force" in errors
    assert "no .tlog" in errors
