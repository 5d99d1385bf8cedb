"""How `make test` spreads the suite over workers (pytest -n N).

- A test module stays on one worker, in order: module fixtures such as a served vehicle are
  made once, and the REST flight's stages run in sequence.
- The browser tests are split into ``BROWSER_GROUPS`` groups, each on one worker: a browser
  rendering WebGL in software takes a core, so no more than that run at once. The modules of
  one family of tests/browser/sharing.py go to one group, one after another: they share a
  server.
- The longest modules start first (longest processing time first): a 90 s module started
  last would leave the other workers idle while it runs. ``MODULE_SECONDS`` holds what each
  took in a run with ``--durations=0`` (beside two busy loops); a module not listed counts
  as ``UNLISTED_S`` and keeps its place in the collection order among the rest.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from server.link.stream import stream_channel
from server.link.stream.sender_supervisor import SenderSupervisor
from tests.browser.sharing import FAMILY_OF

# SKYHELM_TEST_CPU_LOG=path: each test's CPU seconds, its processes' included (tests/cpu_account.py)
pytest_plugins = ["tests.cpu_account"]

_BROWSER_TESTS = "tests/browser/"
BROWSER_GROUPS = 2
UNLISTED_S = 5.0
MODULE_SECONDS: dict[str, float] = {
    "tests/browser/test_layout.py": 186,
    "tests/browser/test_dashboard_quad.py": 74,
    "tests/browser/test_dashboard_handover.py": 72,
    "tests/browser/test_instruments.py": 54,
    "tests/browser/test_fleet_view.py": 52,
    "tests/browser/test_scene_panel.py": 51,
    "tests/browser/test_ready_to_fly.py": 33,
    "tests/browser/test_page_draws.py": 32,
    "tests/browser/test_sliders.py": 31,
    "tests/browser/test_control_after_restart.py": 23,
    "tests/browser/test_map.py": 23,
    "tests/browser/test_offboard_follow.py": 19,
    "tests/browser/test_dashboard_vtol.py": 18,
    "tests/browser/test_csp.py": 16,
    "tests/browser/test_alerts.py": 14,
    "tests/browser/test_plots.py": 12,
    "tests/browser/test_dashboard_sticks.py": 12,
    "tests/browser/test_params_editor.py": 10,
    "tests/api/test_schemathesis_cli.py": 171,
    "tests/client/test_flow_chain.py": 144,
    "tests/api/test_openapi_fuzz.py": 131,
    "tests/api/test_control_ws.py": 121,
    "tests/api/test_ws.py": 88,
    "tests/faults/test_stream_sender.py": 60,
    "tests/faults/test_stream_sender_served.py": 55,
    "tests/api/test_rest_flight.py": 64,
    "tests/faults/test_radio_faults.py": 58,
    "tests/sim/test_rtl_fixed_wing.py": 56,
    "tests/fleet/test_fleet_processes.py": 56,
    "tests/test_cli.py": 39,
    "tests/faults/test_pilot_gone.py": 36,
    "tests/peers/test_mavsdk.py": 34,
    "tests/client/test_readme_session.py": 33,
    "tests/link/test_vehicle_sim.py": 32,
    "tests/link/test_intents.py": 30,
    "tests/client/test_standalone_install.py": 29,
    "tests/faults/test_loss.py": 27,
    "tests/api/test_sticks.py": 24,
    "tests/api/test_ready_to_fly.py": 23,
    "tests/client/test_sync_client.py": 22,
    "tests/link/test_mavproxy_router.py": 21,
    "tests/link/test_truthful_answers.py": 21,
    "tests/api/test_flight.py": 21,
    "tests/faults/test_unanswered.py": 21,
    "tests/sim/test_vtol_transition.py": 20,
    "tests/faults/test_server_kill.py": 19,
    "tests/api/test_ws_and_stateful_fuzz.py": 19,
    "tests/foxglove/test_live.py": 18,
    "tests/client/test_typed_answers.py": 18,
    "tests/faults/test_linkloss.py": 17,
    "tests/client/test_async_client.py": 17,
    "tests/sim/test_flight_timing.py": 16,
    "tests/api/test_intents.py": 16,
    "tests/sim/test_fixed_wing.py": 16,
    "tests/sim/test_navigator.py": 16,
    "tests/faults/test_signing_faults.py": 14,
    "tests/link/test_arming_modes.py": 14,
    "tests/faults/test_reboot.py": 13,
    "tests/bench/test_report.py": 13,
    "tests/sim/test_streams.py": 13,
    "tests/api/test_truthful_answers.py": 13,
    "tests/test_calls.py": 13,
    "tests/api/test_control_rest.py": 13,
    "tests/client/test_intents_client.py": 12,
    "tests/fleet/test_edge.py": 12,
    "tests/faults/test_hostile_input.py": 10,
    "tests/faults/test_faultproxy.py": 10,
    "tests/sim/test_cli.py": 9,
}


# What a server keeps for its user (the generated token, PX4's metadata) goes to directories
# of the run, never to the real home: set before any test and before the workers start
# (they inherit the environment).
_KEPT = {
    "XDG_STATE_HOME": "state",
    "XDG_CONFIG_HOME": "config",
    "SKYHELM_CACHE_DIR": "cache",
}


def pytest_configure(config: pytest.Config) -> None:
    if os.environ.get("PYTEST_XDIST_WORKER"):
        return  # the controller set them
    home = Path(tempfile.mkdtemp(prefix="skyhelm-tests-"))
    for name, folder in _KEPT.items():
        os.environ[name] = str(home / folder)
    config.add_cleanup(lambda: shutil.rmtree(home, ignore_errors=True))


@pytest.fixture(autouse=True)
def _root_logging_kept() -> Iterator[None]:
    """The root logger as it was before the test: a test that runs a command in this process
    (``skyhelm serve`` refusing its settings, ``skyhelm convert``) has it log to that test's
    captured stderr, which is closed after it; every later log line of the worker then
    printed a "Logging error" with its stack."""
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    yield
    root.handlers[:] = handlers
    root.setLevel(level)


@pytest.fixture
def supervisor(monkeypatch: pytest.MonkeyPatch) -> Iterator[SenderSupervisor]:
    """A supervisor (and sender process) of this test's own, as the
    server's (stream_channel), closed after it."""
    sup = SenderSupervisor(stream_channel.SenderProcess)
    monkeypatch.setattr(stream_channel, "_supervisor", sup)
    yield sup
    sup.close()


def _module(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


def browser_groups(modules: list[str]) -> dict[str, str]:
    """Each browser module's group: the longest family (or module alone) first into the group
    with least so far."""
    units: dict[str, list[str]] = {}
    for module in modules:
        units.setdefault(FAMILY_OF.get(module, module), []).append(module)

    def unit_s(unit: str) -> float:
        return sum(MODULE_SECONDS.get(m, UNLISTED_S) for m in units[unit])

    totals = [0.0] * BROWSER_GROUPS
    group_of: dict[str, str] = {}
    for unit in sorted(units, key=lambda u: (-unit_s(u), u)):
        least = totals.index(min(totals))
        totals[least] += unit_s(unit)
        for module in units[unit]:
            group_of[module] = f"{_BROWSER_TESTS}group-{least}"
    return group_of


def _scope_seconds(items: list[pytest.Item]) -> dict[str, float]:
    modules = sorted({_module(item.nodeid) for item in items})
    groups = browser_groups([m for m in modules if m.startswith(_BROWSER_TESTS)])
    seconds: dict[str, float] = {}
    for module in modules:
        scope = groups.get(module, module)
        seconds[scope] = seconds.get(scope, 0.0) + MODULE_SECONDS.get(module, UNLISTED_S)
    return seconds


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    modules = sorted({_module(item.nodeid) for item in items})
    groups = browser_groups([m for m in modules if m.startswith(_BROWSER_TESTS)])
    seconds = _scope_seconds(items)
    first_seen: dict[str, int] = {}
    for index, item in enumerate(items):
        first_seen.setdefault(groups.get(_module(item.nodeid), _module(item.nodeid)), index)

    # within a browser group, a family's modules one after another (where its first one was)
    unit_seen: dict[str, int] = {}
    for index, item in enumerate(items):
        unit_seen.setdefault(FAMILY_OF.get(_module(item.nodeid), _module(item.nodeid)), index)

    def order(pair: tuple[int, pytest.Item]) -> tuple[float, int, int, int]:
        index, item = pair
        module = _module(item.nodeid)
        scope = groups.get(module, module)
        return (-seconds[scope], first_seen[scope], unit_seen[FAMILY_OF.get(module, module)],
                index)

    items[:] = [item for _, item in sorted(enumerate(items), key=order)]


def pytest_xdist_make_scheduler(config: Any, log: Any) -> Any:
    from xdist.scheduler import LoadFileScheduling

    # the order comes from pytest_collection_modifyitems (longest first), not the test count
    config.option.loadscopereorder = False
    groups: dict[str, str] = {}

    class _ModuleScheduling(LoadFileScheduling):  # type: ignore[misc]
        def _split_scope(self, nodeid: str) -> str:
            module = _module(nodeid)
            if not module.startswith(_BROWSER_TESTS):
                return str(super()._split_scope(nodeid))
            if not groups:  # the whole collection is known once scheduling starts
                collected = {_module(n) for n in (self.collection or [nodeid])}
                groups.update(browser_groups(sorted(m for m in collected
                                                    if m.startswith(_BROWSER_TESTS))))
            return groups.get(module, f"{_BROWSER_TESTS}group-0")

    return _ModuleScheduling(config, log)
