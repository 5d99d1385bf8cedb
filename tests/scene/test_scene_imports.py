"""viser is half a second of imports: a server without the 3D scene (``--no-scene``, the
tests' in-process apps) and the Foxglove bridge, which shares the scene's socket proxy, do
not load it; a server with the scene does."""

from __future__ import annotations

import json
import subprocess
import sys

_LOADED = (
    "import json, sys\n"
    "from server.app import create_app\n"
    "from server.settings import load_settings\n"
    "import server.foxglove\n"
    "create_app(load_settings(connect=[], token='pilot-token-for-tests', scene={scene},"
    " log_dir=None, web_dir=None))\n"
    "print(json.dumps('viser' in sys.modules))\n"
)


def _viser_loaded(scene: bool) -> bool:
    run = subprocess.run([sys.executable, "-c", _LOADED.format(scene=scene)],
                         capture_output=True, text=True, timeout=60, check=True)
    loaded: bool = json.loads(run.stdout.strip().splitlines()[-1])
    return loaded


def test_a_server_without_the_scene_loads_no_viser() -> None:
    assert _viser_loaded(scene=False) is False


def test_a_server_with_the_scene_loads_it() -> None:
    assert _viser_loaded(scene=True) is True
