"""Run every benchmark in bench/ one after another, then write docs/PERFORMANCE.md (what
`make bench` does).

Each benchmark prints its figures and writes bench/results/<name>.json itself; this runner
sequences them so their numbers come from one run on one machine, times each one against
the run's budget, and then runs bench/report.py, which counts only the results written in
this run. The run's timings go to bench/results/run_all.json.

    .venv/bin/python -m bench.run_all                 # default sizes (~9 min on 2 cores)
    .venv/bin/python -m bench.run_all --quick         # a smoke run with small sizes
    .venv/bin/python -m bench.run_all --only api_load,signing
    .venv/bin/python -m bench.run_all --soak          # adds the 30-minute soak
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

BENCH_DIR = Path(__file__).resolve().parent
NOT_BENCHES = {"__init__", "run_all", "report"}
# Long runs, only when asked: SKYHELM_BENCH_SOAK=1 (or --soak) adds the 30-minute soaks.
OPT_IN = {"soak": "SKYHELM_BENCH_SOAK", "radio_soak": "SKYHELM_BENCH_SOAK"}
# The whole default run on a 2-core machine, and what one benchmark may take of it.
BUDGET_S = 15 * 60.0
PER_BENCH_BUDGET_S = 90.0
# A benchmark that hangs is stopped after this long; the run goes on without it.
PER_BENCH_TIMEOUT_S = 600.0
# Arguments this run gives a benchmark in place of its own defaults, to keep it within
# PER_BENCH_BUDGET_S (the bench's own defaults stay its long run).
DEFAULT_ARGS: dict[str, list[str]] = {
    # the sim against PX4's recorded figures (~45 s); flying real PX4 SITL beside it takes
    # ~10 min: `python -m bench.parity_timing` alone, or `make test-px4`
    "parity_timing": ["--runs", "1", "--no-px4"],
}
# --quick: smaller sizes for benchmarks without a --quick flag of their own.
QUICK_ARGS: dict[str, list[str]] = {
    "parity_timing": ["--runs", "1", "--no-px4"],
    "api_load": ["--seconds", "5", "--clients", "20"],
    "command_latency": ["--count", "5"],
    "hostile_input": ["--frames", "3000"],
    "manual_control_rate": ["--seconds", "2"],
    "map_render": ["--seconds", "3"],
    "sim_cost": ["--seconds", "2", "--counts", "1,5"],
    "soak": ["--minutes", "1"],
    "radio_soak": ["--minutes", "0.5", "--heartbeat-drops", "1"],
}


# --quick leaves out what is no performance figure: the docs' screenshots (~100 s).
QUICK_SKIP = {"screenshots"}


def discover(bench_dir: Path = BENCH_DIR) -> list[str]:
    return sorted(p.stem for p in bench_dir.glob("*.py")
                  if not p.stem.startswith("_") and p.stem not in NOT_BENCHES)


def arguments(name: str, quick: bool, bench_dir: Path = BENCH_DIR) -> list[str]:
    """What the benchmark is run with: its quick flag or sizes when quick, else this run's
    default sizes."""
    if not quick:
        return list(DEFAULT_ARGS.get(name, []))
    if '"--quick"' in (bench_dir / f"{name}.py").read_text():
        return ["--quick"]
    return list(QUICK_ARGS.get(name, []))


def _csv(text: str) -> set[str]:
    return {part.strip().removesuffix(".py") for part in text.split(",") if part.strip()}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes: a smoke run")
    parser.add_argument("--only", type=_csv, default=None, metavar="A,B",
                        help="run only these benchmarks")
    parser.add_argument("--skip", type=_csv, default=set(), metavar="A,B",
                        help="leave these benchmarks out")
    parser.add_argument("--soak", action="store_true", help="add the 30-minute soak")
    parser.add_argument("--no-report", action="store_true",
                        help="do not write docs/PERFORMANCE.md afterwards")
    args = parser.parse_args(argv)

    wanted_opt_in = {name for name, env in OPT_IN.items()
                     if args.soak or os.environ.get(env) == "1"}
    names = [n for n in discover()
             if (n not in OPT_IN or n in wanted_opt_in or (args.only and n in args.only))
             and (args.only is None or n in args.only) and n not in args.skip
             and not (args.quick and n in QUICK_SKIP and not (args.only and n in args.only))]
    started_at = dt.datetime.now(dt.UTC).replace(microsecond=0)
    run_start = time.monotonic()
    timings: list[dict[str, Any]] = []
    for name in names:
        bench_args = arguments(name, args.quick)
        print(f"\n=== {name} {' '.join(bench_args)} ===", flush=True)
        started = time.monotonic()
        try:
            proc = subprocess.run([sys.executable, "-m", f"bench.{name}", *bench_args],
                                  cwd=BENCH_DIR.parent, timeout=PER_BENCH_TIMEOUT_S)
            code: int | str = proc.returncode
        except subprocess.TimeoutExpired:
            code = "timeout"
        took = time.monotonic() - started
        over = not args.quick and took > PER_BENCH_BUDGET_S
        print(f"--- {name}: exit {code} after {took:.0f} s"
              + (f" (over the {PER_BENCH_BUDGET_S:.0f} s per-benchmark budget)" if over else ""),
              flush=True)
        timings.append({"bench": name, "args": bench_args, "exit": code,
                        "seconds": round(took, 1), "over_budget": over})
    total = time.monotonic() - run_start

    print(f"\n{'benchmark':24} {'s':>6}  exit")
    for t in timings:
        flag = "  over budget" if t["over_budget"] else ""
        print(f"{t['bench']:24} {t['seconds']:6.0f}  {t['exit']}{flag}")
    print(f"{'total':24} {total:6.0f}  (budget {BUDGET_S:.0f} s)")
    if not args.quick and total > BUDGET_S:
        print(f"the run took {total:.0f} s, over its {BUDGET_S:.0f} s budget")
    failed = [t["bench"] for t in timings if t["exit"] != 0]
    results_dir = BENCH_DIR / "results"
    results_dir.mkdir(parents=True, exist_ok=True)
    (results_dir / "run_all.json").write_text(json.dumps({
        "started_at": started_at.isoformat().replace("+00:00", "Z"),
        "quick": args.quick,
        "total_seconds": round(total, 1),
        "budget_seconds": BUDGET_S,
        "benches": timings,
    }, indent=2) + "\n")

    report_code = 0
    if not args.no_report:
        print("\n=== report ===", flush=True)
        report_code = subprocess.run(
            [sys.executable, "-m", "bench.report", "--since", started_at.isoformat()],
            cwd=BENCH_DIR.parent).returncode
    if failed:
        print("failed:", ", ".join(failed))
    return 1 if failed or report_code else 0


if __name__ == "__main__":
    raise SystemExit(main())
