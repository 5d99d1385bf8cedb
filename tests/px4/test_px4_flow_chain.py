"""The whole chain of documented flows (tests/flow_chain.py) against real PX4 v1.16 SITL,
with `skyhelm serve --connect udpin:...` and default settings: whatever the instance, the
flows find the vehicle by its system id; none needs `force`."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.browser.harness import chromium_context
from tests.flow_chain import Chain, full_chain
from tests.px4.conftest import Px4Sitl
from tests.serve_process import Served

pytestmark = [
    pytest.mark.px4,
    pytest.mark.timeout(2400),
    pytest.mark.skipif(shutil.which("curl") is None, reason="needs curl"),
]


def test_px4_every_documented_flow_runs_again_and_again(
    px4: Px4Sitl, served_px4: Served, tmp_path: Path
) -> None:
    chain = Chain(served_px4.base_url, served_px4.pilot_token, tmp_path, vehicle=px4.sysid,
                  server_log=served_px4.stderr_path)
    with chromium_context() as context:
        full_chain(chain, context)
