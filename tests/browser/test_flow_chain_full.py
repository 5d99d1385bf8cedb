"""The whole chain of documented flows (tests/flow_chain.py: the README session three times,
the examples, a page flight, the README session again, scripts killed half-way, the
docs/api.md session) on the simulated quad at real speed, with default server settings.
About ten minutes: opt-in with `make test-chain`; `make test` runs a shorter chain
(tests/client/test_flow_chain.py)."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest

from tests.flow_chain import Chain, full_chain

from .harness import Serve

pytestmark = [
    pytest.mark.chain,
    pytest.mark.timeout(1800),
    pytest.mark.skipif(shutil.which("curl") is None, reason="needs curl"),
]
SERVE_ARGS = ["--no-scene"]


def test_every_documented_flow_runs_again_and_again(
    browser: Any, serve: Serve, tmp_path: Path
) -> None:
    full_chain(Chain(serve.base, serve.token, tmp_path), browser)
