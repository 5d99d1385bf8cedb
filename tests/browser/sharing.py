"""Browser modules that share one `skyhelm serve` on their worker: each has the same
SERVE_ARGS as the others of its family and every test first puts the vehicle in the state it
needs (tests/browser/flows.py settle_vehicle), so a server left by an earlier module serves it
as well as a fresh one. A family runs on one worker, its modules one after another
(tests/conftest.py), and its server stops when the worker goes on to another module.

Not in a family: modules that need a vehicle as fresh as a new server's (a full battery and
no health warning, at the origin, a landed state that never changes)."""

from __future__ import annotations

SHARED_SERVE_FAMILIES: dict[str, tuple[str, ...]] = {
    "quad at 3x": (
        "tests/browser/test_dashboard_quad.py",
        "tests/browser/test_dashboard_handover.py",
        "tests/browser/test_map.py",
        "tests/browser/test_dashboard_sticks.py",
    ),
    "quad at 2x": (
        "tests/browser/test_instruments.py",
        "tests/browser/test_alerts.py",
        "tests/browser/test_plots.py",
        "tests/browser/test_offboard_follow.py",
    ),
}
FAMILY_OF: dict[str, str] = {
    module: family for family, modules in SHARED_SERVE_FAMILIES.items() for module in modules
}
