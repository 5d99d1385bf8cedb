"""Run every benchmark in bench/ one after another (what `make bench` does).

Each benchmark prints its figures and writes bench/results/<name>.json itself; this runner
only sequences them so their numbers come from one run on one machine.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

BENCH_DIR = Path(__file__).resolve().parent
SKIP = {"__init__.py", "run_all.py"}
# Long runs, only when asked: SKYHELM_BENCH_SOAK=1 (or --soak) adds the 30-minute soak.
OPT_IN = {"soak.py": "SKYHELM_BENCH_SOAK"}


def main() -> int:
    wanted = {name for name, env in OPT_IN.items()
              if os.environ.get(env) == "1" or "--soak" in sys.argv[1:]}
    scripts = sorted(
        p for p in BENCH_DIR.glob("*.py")
        if p.name not in SKIP and not p.name.startswith("_")
        and (p.name not in OPT_IN or p.name in wanted)
    )
    failed: list[str] = []
    for script in scripts:
        print(f"\n=== {script.stem} ===", flush=True)
        started = time.monotonic()
        proc = subprocess.run([sys.executable, "-m", f"bench.{script.stem}"], cwd=BENCH_DIR.parent)
        print(f"--- {script.stem}: exit {proc.returncode} after {time.monotonic() - started:.0f} s")
        if proc.returncode != 0:
            failed.append(script.stem)
    if failed:
        print("failed:", ", ".join(failed))
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
