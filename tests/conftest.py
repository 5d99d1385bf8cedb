"""How `make test` spreads the suite over workers (pytest -n N): a test module stays on one
worker, in order (module fixtures such as a served vehicle are made once, and the REST
flight's stages run in sequence), and the browser tests share one worker, since a browser
rendering WebGL in software takes a core."""

from __future__ import annotations

from typing import Any

_BROWSER_TESTS = "tests/browser/"


def pytest_xdist_make_scheduler(config: Any, log: Any) -> Any:
    from xdist.scheduler import LoadFileScheduling

    class _ModuleScheduling(LoadFileScheduling):  # type: ignore[misc]
        def _split_scope(self, nodeid: str) -> str:
            if nodeid.startswith(_BROWSER_TESTS):
                return _BROWSER_TESTS
            return str(super()._split_scope(nodeid))

    return _ModuleScheduling(config, log)
