"""`skyhelm serve` as the Docker image runs it: a real subprocess that starts the simulated
vehicle, prints one URL, answers with the token, and takes the sim down on Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import httpx
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from server.cli import RedactTokens, build_parser, settings_from_args
from server.settings import SettingsError
from tests.waiting import wait_for_blocking

SKYHELM = Path(sys.executable).with_name("skyhelm")
READY_PREFIX = "SkyHelm ready: "


def _children(pid: int) -> list[int]:
    children: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        text = (task / "children").read_text().split()
        children += [int(child) for child in text]
    return children


def _gone(pid: int) -> bool:
    stat = Path(f"/proc/{pid}/stat")
    try:
        return stat.read_text().split(") ")[1].startswith("Z")
    except FileNotFoundError:
        return True


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads process children from /proc")
def test_serve_prints_url_answers_and_stops_sim_on_sigint(tmp_path: Path) -> None:
    command = [str(SKYHELM), "serve", "--port", "0", "--sim-speed", "2", "--log-dir", str(tmp_path)]
    stderr_path = tmp_path / "stderr.log"
    with stderr_path.open("w") as stderr:
        server = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=stderr, text=True)
        try:
            assert server.stdout is not None
            line = server.stdout.readline()
            assert line.startswith(READY_PREFIX), line
            url = line.removeprefix(READY_PREFIX).strip()
            base, _, token = url.partition("/?token=")
            assert base.startswith("http://127.0.0.1:")
            assert len(token) >= 16

            assert httpx.get(f"{base}/api/v1/health").json()["status"] == "ok"
            assert httpx.get(f"{base}/api/v1/vehicles").status_code == 401
            vehicles = httpx.get(
                f"{base}/api/v1/vehicles", headers={"Authorization": f"Bearer {token}"}
            ).json()
            assert [v["id"] for v in vehicles] == [1]
            assert httpx.get(f"{base}/api/v1/vehicles", params={"token": token}).status_code == 200
            ws_url = base.replace("http://", "ws://") + f"/api/v1/ws/telemetry?token={token}"
            with connect(ws_url) as ws:  # uvicorn logs WebSocket paths: the filter must act
                seen: list[str] = []
                while "state" not in seen:  # the vehicle list and events may come first
                    assert len(seen) < 50, seen
                    seen.append(json.loads(ws.recv(timeout=10))["type"])

            sims = _children(server.pid)
            assert sims, "the simulated vehicle runs as a child process"
            server.send_signal(signal.SIGINT)
            assert server.wait(timeout=20) == 0
            wait_for_blocking(
                "the sim child to end after SIGINT", lambda: all(_gone(pid) for pid in sims), 10.0
            )
            assert server.stdout.read() == "", "exactly one line on stdout"
        finally:
            if server.poll() is None:
                server.kill()
                server.wait()
    log = stderr_path.read_text()
    assert token not in log, "the token must never be logged"
    assert "token=***" in log, "the WebSocket line is logged, redacted"
    assert list(tmp_path.glob("*.tlog")), "the session is recorded"


def test_bad_setting_values_exit_2_with_a_clear_message() -> None:
    result = subprocess.run(
        [str(SKYHELM), "serve", "--port", "99999", "--on-operator-loss", "panic"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert "port" in result.stderr
    assert "on_operator_loss" in result.stderr
    assert "hold-mode" in result.stderr
    assert result.stdout == ""


def test_cli_flags_beat_environment_which_beats_toml(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = tmp_path / "skyhelm.toml"
    config.write_text('port = 9001\nrate_hz = 30.0\nlease_ttl_s = 5.0\non_operator_loss = "land"\n')
    monkeypatch.setenv("SKYHELM_RATE_HZ", "40")
    monkeypatch.setenv("SKYHELM_LEASE_TTL_S", "3")
    args = build_parser().parse_args(["serve", "--config", str(config), "--lease-ttl-s", "1.5"])
    settings = settings_from_args(args)
    assert settings.port == 9001  # TOML
    assert settings.rate_hz == 40.0  # env over TOML
    assert settings.lease_ttl_s == 1.5  # flag over env
    assert settings.on_operator_loss == "land"


def test_connect_flag_repeats_and_env_takes_a_comma_list(monkeypatch: pytest.MonkeyPatch) -> None:
    args = build_parser().parse_args(
        ["serve", "--connect", "udpin:127.0.0.1:0", "--connect", "tcp:127.0.0.1:5760"]
    )
    assert settings_from_args(args).connect == ["udpin:127.0.0.1:0", "tcp:127.0.0.1:5760"]
    monkeypatch.setenv("SKYHELM_CONNECT", "udpin:127.0.0.1:0,udpout:127.0.0.1:9")
    env_only = settings_from_args(build_parser().parse_args(["serve"]))
    assert env_only.connect == ["udpin:127.0.0.1:0", "udpout:127.0.0.1:9"]


def test_serve_takes_up_to_a_hundred_simulated_vehicles() -> None:
    for count in (33, 50, 100):
        args = build_parser().parse_args(["serve", "--sim-count", str(count)])
        assert settings_from_args(args).sim_count == count
    with pytest.raises(SettingsError, match="sim_count"):
        settings_from_args(build_parser().parse_args(["serve", "--sim-count", "101"]))


def test_bad_connect_url_and_missing_config_are_refused(tmp_path: Path) -> None:
    with pytest.raises(SettingsError, match="connect"):
        settings_from_args(build_parser().parse_args(["serve", "--connect", "carrier-pigeon"]))
    with pytest.raises(SettingsError, match="does not exist"):
        settings_from_args(
            build_parser().parse_args(["serve", "--config", str(tmp_path / "none.toml")])
        )


def _serve_token(*args: str) -> str:
    return settings_from_args(build_parser().parse_args(["serve", *args])).pilot_token()


def test_generated_token_is_kept_in_a_0600_file_and_a_given_token_wins(tmp_path: Path) -> None:
    kept = tmp_path / "kept" / "token"
    first = _serve_token("--token-file", str(kept))
    assert len(first) >= 24
    assert _serve_token("--token-file", str(kept)) == first  # the next start: the same
    assert kept.read_text().strip() == first
    assert kept.stat().st_mode & 0o777 == 0o600
    assert kept.parent.stat().st_mode & 0o777 == 0o700
    assert _serve_token("--token-file", str(tmp_path / "other")) != first  # a new file: random
    given = _serve_token("--token-file", str(kept), "--token", "s3cret-token")
    assert given == "s3cret-token"
    assert kept.read_text().strip() == first  # a given token is not written


def test_a_token_file_others_can_read_is_made_0600_and_kept(tmp_path: Path) -> None:
    kept = tmp_path / "token"
    kept.write_text("an-older-token-1234\n")
    kept.chmod(0o644)
    assert _serve_token("--token-file", str(kept)) == "an-older-token-1234"
    assert kept.stat().st_mode & 0o777 == 0o600


def test_the_token_file_is_in_the_xdg_state_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    token = _serve_token()
    assert (tmp_path / "state" / "skyhelm" / "token").read_text().strip() == token
    monkeypatch.setenv("SKYHELM_TOKEN_FILE", str(tmp_path / "from-env"))
    assert _serve_token() == (tmp_path / "from-env").read_text().strip() != token


def test_the_suite_keeps_nothing_in_the_real_home() -> None:
    """tests/conftest.py points the token file and the metadata cache at the run's own
    directory (and `skyhelm serve` children inherit it)."""
    home = Path.home().resolve()
    for name in ("XDG_STATE_HOME", "XDG_CONFIG_HOME", "SKYHELM_CACHE_DIR"):
        assert not Path(os.environ[name]).resolve().is_relative_to(home), name


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


def _printed_url(args: list[str], env: dict[str, str], log: Path) -> str:
    """Start `skyhelm serve`, take the URL it prints, stop it with Ctrl-C."""
    with log.open("a") as stderr:
        server = subprocess.Popen(
            [str(SKYHELM), "serve", *args], stdout=subprocess.PIPE, stderr=stderr, text=True,
            env=env,
        )  # fmt: skip
        try:
            assert server.stdout is not None
            line = server.stdout.readline()
            assert line.startswith(READY_PREFIX), (line, log.read_text()[-2000:])
            server.send_signal(signal.SIGINT)
            assert server.wait(timeout=30) == 0
            return line.removeprefix(READY_PREFIX).strip()
        finally:
            if server.poll() is None:
                server.kill()
                server.wait()


def test_two_starts_print_the_same_url(tmp_path: Path) -> None:
    env = {**os.environ, "XDG_STATE_HOME": str(tmp_path / "state")}
    env.pop("SKYHELM_TOKEN_FILE", None)
    args = ["--port", str(_free_port()), "--no-scene", "--no-tlog"]
    log = tmp_path / "stderr.log"
    first = _printed_url(args, env, log)
    second = _printed_url(args, env, log)
    assert first == second
    token = (tmp_path / "state" / "skyhelm" / "token").read_text().strip()
    assert first.endswith(f"/?token={token}")
    assert token not in log.read_text(), "the token must never be logged"
    given = _printed_url([*args, "--token", "s3cret-token"], env, log)
    assert given.endswith("/?token=s3cret-token")


def test_log_filter_redacts_tokens_in_urls() -> None:
    import logging

    record = logging.LogRecord(
        "uvicorn.error",
        logging.INFO,
        __file__,
        1,
        '%s - "WebSocket %s" [accepted]',
        ("127.0.0.1", "/api/v1/ws/telemetry?token=abc&x=1"),
        None,
    )
    assert RedactTokens().filter(record)
    assert "abc" not in record.getMessage()
    assert "token=***&x=1" in record.getMessage()


def test_sim_subcommand_execs_python_m_sim() -> None:
    result = subprocess.run(
        [str(SKYHELM), "sim", "--help"],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ},
    )
    assert result.returncode == 0
    assert "--airframe" in result.stdout


def test_ready_url_names_a_reachable_host_when_bound_to_all_interfaces() -> None:
    from server.cli import ready_url

    settings = settings_from_args(
        build_parser().parse_args(["serve", "--host", "0.0.0.0", "--token", "s3cret-token"])
    )
    assert ready_url(settings, 8123) == "http://127.0.0.1:8123/?token=s3cret-token"


def _write_recording(path: Path, duration_s: int) -> None:
    """A .tlog of a quad beating at 1 Hz, with our own GCS heartbeat interleaved."""
    import asyncio

    from pymavlink.dialects.v20 import development as mavlink

    from server.link.codec.tlog import TlogWriter

    vehicle = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    writer = TlogWriter(path)
    for second in range(duration_s):
        quad = vehicle.heartbeat_encode(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 1, 0x3040000, 3, 3
        )
        ours = gcs.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 4)
        for mav, msg in ((vehicle, quad), (gcs, ours)):
            writer.record(msg.pack(mav), unix_time_s=1.7e9 + second)
            mav.seq = (mav.seq + 1) % 256
    asyncio.run(writer.close())


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads process children from /proc")
def test_replay_serves_the_recorded_vehicle_read_only_and_stops_on_sigint(tmp_path: Path) -> None:
    recording = tmp_path / "flight.tlog"
    _write_recording(recording, duration_s=10)
    command = [str(SKYHELM), "replay", str(recording), "--port", "0", "--speed", "5", "--loop",
               "--no-scene"]  # fmt: skip
    server = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=tmp_path
    )
    try:
        assert server.stdout is not None
        line = server.stdout.readline()
        assert line.startswith(READY_PREFIX), line
        base, _, token = line.removeprefix(READY_PREFIX).strip().partition("/?token=")
        auth = {"Authorization": f"Bearer {token}"}

        vehicles = wait_for_blocking(
            "the recorded vehicle",
            lambda: httpx.get(f"{base}/api/v1/vehicles", headers=auth).json(),
            10.0,
            every_s=0.05,
        )
        assert [v["id"] for v in vehicles] == [1]
        assert httpx.get(f"{base}/api/v1/health").json()["read_only"] is True
        assert not _children(server.pid), "a replay starts no simulated vehicle"
        for path in ("/api/v1/vehicles/1/control", "/api/v1/vehicles/1/arm"):
            refused = httpx.post(f"{base}{path}", headers=auth)
            assert refused.status_code == 403, path
            assert "read-only replay" in refused.json()["detail"]["reason"]
        control_url = f"{base.replace('http://', 'ws://')}/api/v1/ws/control?token={token}&vehicle=1"
        with connect(control_url) as ws, pytest.raises(ConnectionClosed) as closed:
            ws.recv(timeout=10)
        assert closed.value.rcvd is not None
        assert (closed.value.rcvd.code, closed.value.rcvd.reason[:16]) == (4403, "read-only replay")

        server.send_signal(signal.SIGINT)
        assert server.wait(timeout=20) == 0
    finally:
        if server.poll() is None:
            server.kill()
            server.wait()
    assert not (tmp_path / "logs").exists(), "a replay records nothing"


def test_replay_of_a_missing_file_exits_2(tmp_path: Path) -> None:
    result = subprocess.run(
        [str(SKYHELM), "replay", str(tmp_path / "none.tlog"), "--port", "0"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert "no recording" in result.stderr


def test_a_map_tile_file_that_is_no_archive_exits_2(tmp_path: Path) -> None:
    not_tiles = tmp_path / "field.mbtiles"
    not_tiles.write_text("not an archive")
    result = subprocess.run(
        [str(SKYHELM), "serve", "--port", "0", "--no-scene", "--no-tlog",
         "--connect", "udpin:127.0.0.1:0", "--map-tiles", str(not_tiles)],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert result.returncode == 2
    assert "map_tiles" in result.stderr
    assert "neither a PMTiles nor an MBTiles archive" in result.stderr


def test_map_tiles_comes_from_the_flag_environment_or_toml(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = tmp_path / "skyhelm.toml"
    config.write_text('map_tiles = "from-toml.pmtiles"\n')
    parse = build_parser().parse_args
    assert settings_from_args(parse(["serve", "--config", str(config)])).map_tiles == Path(
        "from-toml.pmtiles"
    )
    monkeypatch.setenv("SKYHELM_MAP_TILES", "from-env.mbtiles")
    assert settings_from_args(parse(["serve"])).map_tiles == Path("from-env.mbtiles")
    flag = parse(["serve", "--map-tiles", "field.pmtiles"])
    assert settings_from_args(flag).map_tiles == Path("field.pmtiles")
