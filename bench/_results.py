"""Where every benchmark writes its figures, and the machine facts that go with them."""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path
from typing import Any

RESULTS_DIR = Path(__file__).resolve().parent / "results"


def machine_info(load_average_before: tuple[float, float, float] | None = None) -> dict[str, Any]:
    """CPU count, Python, platform and load averages: figures from a shared machine mean
    little without the load they were measured under."""
    info: dict[str, Any] = {
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "load_average_after": os.getloadavg(),
    }
    if load_average_before is not None:
        info["load_average_before"] = load_average_before
    return info


def write_results(name: str, result: dict[str, Any]) -> Path:
    """Write bench/results/<name>.json and say so, stamped with when it was written (UTC),
    which tells the report (bench/report.py) what the current run measured."""
    result = {**result, "written_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    path = RESULTS_DIR / f"{name}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {path.relative_to(RESULTS_DIR.parent.parent)}")
    return path
