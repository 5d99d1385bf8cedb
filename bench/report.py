"""Write docs/PERFORMANCE.md from the benchmarks' results (the last step of `make bench`).

Each benchmark module in bench/ may define ``report(result) -> Section | None`` (see
bench/_report.py); this imports every module, reads bench/results/<name>.json, calls its
``report`` and writes one document: the machine, the date, how to regenerate it, a summary
of issue 14's done-when targets, then the sections in order with their figures
(docs/img/perf/*.png). A benchmark without a result (or, with ``--since``, without one
written in this run) gets a section that says it was not measured in this run.

    .venv/bin/python -m bench.report [--results bench/results] [--docs docs] [--since ISO]
"""

from __future__ import annotations

import argparse
import datetime as dt
import importlib
import json
import os
import platform
import sys
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench._report import DOCS_DIR, FIGURE_DIR, Section, output_to
from bench._results import RESULTS_DIR

BENCH_DIR = Path(__file__).resolve().parent
NOT_BENCHES = {"__init__", "report", "run_all"}
NOT_MEASURED = "Not measured in this run."
# Where a benchmark without its own report() (or without a result) appears; the report()
# of a benchmark sets its own order.
DEFAULT_ORDER = {
    "stream_vs_mavsdk": 10,
    "command_latency": 20,
    "ws_clients": 30,
    "api_load": 35,
    "state_encode": 40,
    "many_vehicles": 50,
    "sim_cost": 55,
    "physics_step": 60,
    "scene_updates": 70,
    "map_render": 75,
    "fleet": 80,
    "manual_control_rate": 85,
    "security_overhead": 90,
    "signing": 95,
    "hostile_input": 100,
    "soak": 110,
    "radio_soak": 111,
    "screenshots": 200,
}


# ---------------------------------------------------------------- the machine


def machine_now() -> dict[str, Any]:
    """The machine the report is written on: CPUs and their model, RAM, load, OS."""
    model = "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    ram_gib: float | None = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                ram_gib = int(line.split()[1]) / 1024**2
                break
    except OSError:
        pass
    return {
        "cpus": os.cpu_count(),
        "cpu_model": model,
        "ram_gib": ram_gib,
        "load_average": os.getloadavg(),
        "platform": platform.platform(),
        "python": platform.python_version(),
    }


def _machine_markdown(machine: dict[str, Any], now: dt.datetime) -> str:
    ram = f"{machine['ram_gib']:.1f} GiB" if machine.get("ram_gib") else "?"
    load = ", ".join(f"{x:.2f}" for x in machine["load_average"])
    return "\n".join([
        "| | |",
        "|---|---|",
        f"| Written | {now:%Y-%m-%d %H:%M} UTC |",
        f"| CPUs | {machine['cpus']} × {machine['cpu_model']} |",
        f"| RAM | {ram} |",
        f"| Load average (1, 5, 15 min) when written | {load} |",
        f"| OS | {machine['platform']} |",
        f"| Python | {machine['python']} |",
    ])


# ---------------------------------------------------------------- results


@dataclass
class BenchResult:
    name: str
    title: str
    result: dict[str, Any] | None
    # why there is no result to show: missing, or older than this run
    absent_reason: str | None = None


def _title(module: Any, name: str) -> str:
    """A heading from the module's docstring: its first paragraph up to a colon, or its first
    clause when that is still long."""
    doc = (getattr(module, "__doc__", None) or "").strip()
    if not doc:
        return name
    title = " ".join(doc.split("\n\n")[0].split()).split(": ")[0].rstrip(".")
    for stop in (". ", " (", ", ", " - ", " — "):
        if len(title) > 80 and stop in title:
            title = title.split(stop)[0]
    return title


def _written_at(result: dict[str, Any]) -> dt.datetime | None:
    stamp = result.get("written_at")
    if not isinstance(stamp, str):
        return None
    try:
        return dt.datetime.fromisoformat(stamp.replace("Z", "+00:00"))
    except ValueError:
        return None


def load_result(path: Path, since: dt.datetime | None) -> tuple[dict[str, Any] | None, str | None]:
    if not path.exists():
        return None, NOT_MEASURED
    try:
        result = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        return None, f"{NOT_MEASURED} ({path.name} unreadable: {e})"
    if not isinstance(result, dict):
        return None, f"{NOT_MEASURED} ({path.name} is not an object)"
    if since is not None:
        written = _written_at(result)
        if written is None or written < since:
            return None, f"{NOT_MEASURED} (bench/results/{path.name} is from an earlier run)"
    return result, None


def bench_names(bench_dir: Path = BENCH_DIR) -> list[str]:
    return sorted(p.stem for p in bench_dir.glob("*.py")
                  if not p.stem.startswith("_") and p.stem not in NOT_BENCHES)


# ---------------------------------------------------------------- done-when targets


@dataclass
class TargetRow:
    target: str
    measured: str
    passed: bool | None  # None: not measured in this run
    source: str


def _walk(obj: Any, path: str = "") -> Iterable[tuple[str, str, Any]]:
    """(path, key, value) of every dict entry, depth first."""
    if isinstance(obj, dict):
        for key, value in obj.items():
            sub = f"{path}/{key}"
            yield sub, str(key), value
            yield from _walk(value, sub)
    elif isinstance(obj, list):
        for i, value in enumerate(obj):
            yield f"{path}/{i}", str(i), value
            yield from _walk(value, f"{path}/{i}")


def find_number(obj: Any, *keys: str, within: str = "") -> float | None:
    """The first number stored under one of ``keys`` (in that preference) whose path
    contains ``within``."""
    for wanted in keys:
        for path, key, value in _walk(obj):
            if (key == wanted and within in path and isinstance(value, int | float)
                    and not isinstance(value, bool)):
                return float(value)
    return None


def find_row(obj: Any, fields: Sequence[str], value: float) -> dict[str, Any] | None:
    """A dict inside ``obj`` whose field (one of ``fields``) equals ``value``."""
    for _, _, item in _walk({"": obj}):
        if isinstance(item, dict) and any(item.get(f) == value for f in fields):
            return item
    return None


def _ms(value: float | None) -> str:
    return "?" if value is None else f"{value:.1f} ms"


def _stream_target(results: dict[str, dict[str, Any] | None]) -> TargetRow:
    target = ("Under load, SkyHelm's 50 Hz stream p99 \\|interval − period\\| ≤ MAVSDK's at "
              "20 Hz in the same run; no gap > 100 ms")
    r = results.get("stream_vs_mavsdk")
    if r is not None:
        goal = r.get("goal") or {}
        ours = find_number(goal, "skyhelm_50hz_loaded_p99_abs_error_ms")
        theirs = find_number(goal, "mavsdk_20hz_loaded_p99_abs_error_ms")
        phase = next((p for p in r.get("phases", []) if p.get("load") == "loaded"
                      and p.get("variant") == goal.get("variant")), None)
        gap = find_number(phase.get("skyhelm"), "interval_max_ms") if phase else None
        if ours is not None and theirs is not None:
            no_gap = goal.get("no_gap_over_100ms")
            passed = ours <= theirs and (no_gap if isinstance(no_gap, bool)
                                         else gap is not None and gap <= 100.0)
            return TargetRow(target, f"SkyHelm {_ms(ours)} vs MAVSDK {_ms(theirs)} (ratio "
                             f"{ours / theirs:.2f}); largest gap {_ms(gap)}", passed,
                             "stream_vs_mavsdk")
    r = results.get("stream_jitter")  # the older bench: event-loop load, not WS + REST
    if r is not None:
        ours = find_number(r, "skyhelm_50hz_p99_abs_error_ms")
        theirs = find_number(r, "mavsdk_20hz_p99_abs_error_ms")
        row = find_row(r.get("rows", []), ("rate_hz",), 50.0)
        gap = find_number(row, "interval_max_ms") if row else None
        if ours is not None and theirs is not None:
            return TargetRow(target, f"SkyHelm {_ms(ours)} vs MAVSDK {_ms(theirs)} (ratio "
                             f"{ours / theirs:.2f}); largest gap {_ms(gap)} — under event-loop "
                             "load, not WS + REST clients",
                             ours <= theirs and gap is not None and gap <= 100.0,
                             "stream_jitter")
    return TargetRow(target, NOT_MEASURED, None, "stream_vs_mavsdk")


def _contention_target(results: dict[str, dict[str, Any] | None]) -> TargetRow:
    target = ("A busy machine (8 busy loops per core, with and without SkyHelm's own load), "
              "and quiet: SkyHelm's p99 ≤ 0.5× MAVSDK's in the same run, no gap > 100 ms; "
              "one core: no gap > 250 ms; 50 vehicles busy: every p99 ≤ 5 ms")
    r = results.get("stream_contention")
    goals = (r or {}).get("goals") or {}
    scenarios = [goals.get(name) for name in ("quiet", "busy", "busy+load", "one-core")]
    if r is None or not all(isinstance(g, dict) for g in scenarios):
        return TargetRow(target, NOT_MEASURED, None, "stream_contention")
    ratios = ", ".join(f"{name} {goals[name]['ratio']:.3f}" for name in
                       ("quiet", "busy", "busy+load", "one-core")
                       if goals[name].get("ratio") is not None)
    fleet = r.get("fleet") or {}
    passed = (all(g.get("no_gap") and g.get("ratio_met", True) for g in scenarios)
              and bool(goals.get("fleet_every_stream_p99_met")))
    return TargetRow(target, f"p99 ratios {ratios}; 50 vehicles worst p99 "
                     f"{_ms(fleet.get('worst_p99_ms'))}", passed, "stream_contention")


def _clients_target(results: dict[str, dict[str, Any] | None]) -> TargetRow:
    target = ("100 WS telemetry clients at 10 Hz: vehicle → client p99 ≤ 20 ms, server ≤ 50 % "
              "of one core")
    r = results.get("ws_clients")
    row = find_row(r.get("rows", []), ("clients",), 100) if r is not None else None
    if row is not None:
        # the probe clients' latency: the server's, not that of niced load clients
        p99 = find_number(row.get("probe_latency") or row.get("latency"), "p99_ms")
        cpu = find_number(row, "server_cpu_share_of_one_core")
        if p99 is not None and cpu is not None:
            return TargetRow(target, f"p99 {_ms(p99)} ({p99 / 20.0:.2f} × the limit), "
                             f"server {cpu:.0%} of a core", p99 <= 20.0 and cpu <= 0.5,
                             "ws_clients")
    r = results.get("api_load")
    if r is not None and r.get("telemetry_clients") == 100:
        p99 = find_number(r, "telemetry_latency_p99_ms")
        cpu = find_number(r, "server_cpu_share_of_one_core")
        if p99 is not None and cpu is not None:
            return TargetRow(target, f"p99 {_ms(p99)} ({p99 / 20.0:.2f} × the limit), server "
                             f"{cpu:.0%} of a core (with 50 REST reads/s and a 50 Hz stream)",
                             p99 <= 20.0 and cpu <= 0.5, "api_load")
    return TargetRow(target, NOT_MEASURED, None, "ws_clients")


def _vehicles_target(results: dict[str, dict[str, Any] | None]) -> TargetRow:
    target = "One server, 50 vehicles at 20 Hz: every stream p99 error ≤ 5 ms, no gap > 200 ms"
    r = results.get("many_vehicles")
    row = find_row(r.get("rows", []), ("vehicles",), 50) if r is not None else None
    if row is None:
        return TargetRow(target, NOT_MEASURED, None, "many_vehicles")
    silent = row.get("streams_silent") or []
    p99 = find_number(row, "stream_p99_error_ms_worst")
    gap = find_number(row, "stream_max_gap_ms")
    parts = [f"worst p99 error {_ms(p99)}"
             + (f" ({p99 / 5.0:.2f} × the limit)" if p99 is not None else ""),
             f"largest gap {_ms(gap)}"]
    if silent:
        parts.append(f"{len(silent)} streams silent")
    if row.get("page_live") is not None:
        parts.append("page live" if row["page_live"] else "page NOT live")
    passed = (not silent and p99 is not None and gap is not None and p99 <= 5.0
              and gap <= 200.0 and row.get("page_live", True) is not False)
    return TargetRow(target, ", ".join(parts), passed, "many_vehicles")


def _command_target(results: dict[str, dict[str, Any] | None]) -> TargetRow:
    target = "Command round trip (arm → COMMAND_ACK): SkyHelm median ≤ MAVSDK median"
    r = results.get("command_latency")
    ratio = find_number(r, "median_ratio_skyhelm_over_mavsdk") if r else None
    if ratio is None:
        return TargetRow(target, NOT_MEASURED, None, "command_latency")
    return TargetRow(target, f"SkyHelm / MAVSDK = {ratio:.2f}", ratio <= 1.0, "command_latency")


TARGETS: tuple[Callable[[dict[str, dict[str, Any] | None]], TargetRow], ...] = (
    _stream_target, _contention_target, _clients_target, _vehicles_target, _command_target,
)


def targets_markdown(rows: Sequence[TargetRow]) -> str:
    verdict = {True: "pass", False: "**FAIL**", None: "—"}
    lines = ["| Target | Measured | Result | Bench |", "|---|---|---|---|"]
    lines += [f"| {r.target} | {r.measured} | {verdict[r.passed]} | `{r.source}` |"
              for r in rows]
    return "\n".join(lines)


# ---------------------------------------------------------------- the document


def _section_for(module: Any, bench: BenchResult) -> tuple[Section, str | None]:
    """The bench's own section, or a stand-in; with the error when its report() failed."""
    order = DEFAULT_ORDER.get(bench.name, 500)
    if bench.result is None:
        return Section(bench.title, order, bench.absent_reason or NOT_MEASURED), None
    report = getattr(module, "report", None) if module is not None else None
    if report is None:
        keys = ", ".join(f"`{k}`" for k in list(bench.result)[:8] if k != "machine")
        return Section(bench.title, order,
                       f"Figures in `bench/results/{bench.name}.json` ({keys}, …).", ), None
    try:
        section = report(bench.result)
    except Exception:
        error = traceback.format_exc()
        return Section(bench.title, order, f"The report of this benchmark failed:\n\n"
                                           f"```\n{error.strip()}\n```"), error
    return (section if section is not None else Section(bench.title, order, "")), None


def run_markdown(run: dict[str, Any] | None) -> str:
    """How long each benchmark of the run took (bench/results/run_all.json)."""
    if not run:
        return ("Written from the results in bench/results without `bench/run_all.py`: each "
                "section says when its figures were measured.")
    rows = "\n".join(f"| `{b['bench']}` | {' '.join(b.get('args', [])) or 'defaults'} | "
                     f"{b['seconds']:.0f} | {'ok' if b['exit'] == 0 else b['exit']} |"
                     for b in run.get("benches", []))
    kind = "a quick run (smaller sizes)" if run.get("quick") else "default sizes"
    return (f"Started {run['started_at']}, {kind}, {run['total_seconds']:.0f} s in all "
            f"(budget {run['budget_seconds']:.0f} s).\n\n"
            "| Benchmark | Arguments | Seconds | Exit |\n|---|---|---|---|\n" + rows)


def render(sections: Sequence[tuple[str, Section, dict[str, Any] | None]],
           targets: Sequence[TargetRow], machine: dict[str, Any], now: dt.datetime,
           run: dict[str, Any] | None = None) -> str:
    out = [
        "# Performance",
        "",
        "Written by `make bench` (bench/run_all.py runs every benchmark in bench/, then "
        "`python -m bench.report` writes this page from bench/results/*.json). Do not edit by "
        "hand: regenerate it on the machine whose figures you want with",
        "",
        "    make bench                   # every benchmark at its default size, then this page",
        "    .venv/bin/python -m bench.run_all --quick    # a smoke run, smaller sizes",
        "    .venv/bin/python -m bench.report             # this page from the results there are",
        "",
        "Claims are ratios between figures measured in the same run on the same machine; "
        "absolute times depend on the machine and on what else ran on it, so each figure and "
        "each section names the load it was measured under.",
        "",
        "## The machine",
        "",
        _machine_markdown(machine, now),
        "",
        "## Done-when targets (issue 14)",
        "",
        targets_markdown(targets),
        "",
        "## This run",
        "",
        run_markdown(run),
        "",
        "## Contents",
        "",
    ]
    out += [f"- [{s.title}](#{_anchor(s.title)})" for _, s, _ in sections]
    for name, section, result in sections:
        out += ["", f"## {section.title}", ""]
        measured = _measured_line(name, result)
        if measured:
            out += [measured, ""]
        out.append(section.markdown.strip())
        for fig in section.figures:
            out += ["", f"![{fig.caption}]({fig.path})", "", f"*{fig.caption}*"]
    return "\n".join(out).rstrip() + "\n"


def _anchor(title: str) -> str:
    kept = "".join(c for c in title.lower() if c.isalnum() or c in " -_")
    return kept.replace(" ", "-")


def _measured_line(name: str, result: dict[str, Any] | None) -> str:
    if result is None:
        return ""
    machine = result.get("machine") or {}
    parts = [f"`bench/{name}.py`"]
    written = _written_at(result)
    if written is not None:
        parts.append(f"measured {written:%Y-%m-%d %H:%M} UTC")
    load = machine.get("load_average_before") or machine.get("load_average_after")
    if load:
        parts.append(f"load average {load[0]:.2f}")
    elif machine.get("load_average_1min") is not None:
        parts.append(f"load average {machine['load_average_1min']:.2f}")
    if machine.get("cpus"):
        parts.append(f"{machine['cpus']} CPUs")
    return "<sub>" + ", ".join(parts) + "</sub>"


def _this_run(path: Path, since: dt.datetime | None) -> dict[str, Any] | None:
    """bench/run_all.py's timings, when they are those of the run being reported."""
    try:
        run = json.loads(path.read_text())
        started = dt.datetime.fromisoformat(run["started_at"].replace("Z", "+00:00"))
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    return run if since is None or started >= since else None


def write_report(results_dir: Path = RESULTS_DIR, docs_dir: Path = DOCS_DIR,
                 since: dt.datetime | None = None,
                 names: Sequence[str] | None = None) -> tuple[Path, list[str]]:
    """Write ``docs_dir``/PERFORMANCE.md (figures in ``docs_dir``/img/perf); returns the
    path and the benchmarks whose report() failed."""
    import matplotlib

    matplotlib.use("Agg")
    figure_dir = docs_dir / FIGURE_DIR.relative_to(DOCS_DIR)
    if figure_dir.is_dir():
        for old in figure_dir.glob("*.png"):
            old.unlink()
    failed: list[str] = []
    sections: list[tuple[str, Section, dict[str, Any] | None]] = []
    results: dict[str, dict[str, Any] | None] = {}
    with output_to(docs_dir):
        for name in names if names is not None else bench_names():
            result, reason = load_result(results_dir / f"{name}.json", since)
            results[name] = result
            try:
                module = importlib.import_module(f"bench.{name}")
            except Exception:
                print(f"bench.report: cannot import bench.{name}:\n{traceback.format_exc()}",
                      file=sys.stderr)
                failed.append(name)
                module = None
            bench = BenchResult(name, _title(module, name), result, reason)
            section, error = _section_for(module, bench)
            if error is not None:
                print(f"bench.report: {name}.report() failed:\n{error}", file=sys.stderr)
                failed.append(name)
            sections.append((name, section, result))
    sections.sort(key=lambda item: (item[1].order, item[0]))
    targets = [target(results) for target in TARGETS]
    now = dt.datetime.now(dt.UTC)
    path = docs_dir / "PERFORMANCE.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render(sections, targets, machine_now(), now,
                           _this_run(results_dir / "run_all.json", since)))
    return path, failed


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=RESULTS_DIR,
                        help="directory of <bench>.json results")
    parser.add_argument("--docs", type=Path, default=DOCS_DIR,
                        help="writes PERFORMANCE.md and img/perf/*.png here")
    parser.add_argument("--since", type=dt.datetime.fromisoformat, default=None,
                        help="UTC time the run began: older results count as not measured")
    args = parser.parse_args(argv)
    since = args.since.replace(tzinfo=dt.UTC) if args.since and not args.since.tzinfo \
        else args.since
    path, failed = write_report(args.results, args.docs, since)
    print(f"wrote {path}")
    if failed:
        print("report failed for: " + ", ".join(failed), file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
