"""How `make test` spreads the suite over workers (pytest -n N --dist loadgroup): a test
module stays on one worker, in order (module fixtures such as a served vehicle are made once,
and the REST flight's stages run in sequence), and the browser tests share one worker, since
a browser rendering WebGL in software takes a core."""

from __future__ import annotations

from pathlib import Path

import pytest

_BROWSER_TESTS = Path(__file__).parent / "browser"


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        path = Path(str(item.fspath))
        group = "browser" if path.is_relative_to(_BROWSER_TESTS) else str(path)
        item.add_marker(pytest.mark.xdist_group(group))
