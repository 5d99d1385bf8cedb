"""The Foxglove server and MCAP recording are off unless asked for, by flag, environment
or TOML file alike."""

from __future__ import annotations

from pathlib import Path

import pytest

from server.app import _foxglove_bridge
from server.cli import build_parser, settings_from_args
from server.settings import SettingsError, load_settings


def test_off_by_default() -> None:
    settings = load_settings()
    assert (settings.foxglove_port, settings.mcap) == (None, False)
    assert _foxglove_bridge(settings) is None


def test_flags_turn_them_on() -> None:
    args = build_parser().parse_args(["serve", "--foxglove-port", "8765", "--mcap"])
    settings = settings_from_args(args)
    assert (settings.foxglove_port, settings.mcap) == (8765, True)
    bridge = _foxglove_bridge(settings)
    assert bridge is not None
    assert (bridge.requested_port, bridge.record_mcap) == (8765, True)


def test_environment_and_toml_turn_them_on(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("SKYHELM_FOXGLOVE_PORT", "0")
    assert load_settings().foxglove_port == 0
    monkeypatch.delenv("SKYHELM_FOXGLOVE_PORT")
    config = tmp_path / "skyhelm.toml"
    config.write_text("mcap = true\nfoxglove_port = 9000\n")
    settings = load_settings(config)
    assert (settings.foxglove_port, settings.mcap) == (9000, True)


def test_a_port_out_of_range_is_refused_with_its_name() -> None:
    with pytest.raises(SettingsError, match="foxglove_port"):
        load_settings(foxglove_port=70000)


def test_mcap_without_a_log_dir_and_without_a_server_starts_nothing() -> None:
    assert _foxglove_bridge(load_settings(mcap=True, log_dir=None)) is None
