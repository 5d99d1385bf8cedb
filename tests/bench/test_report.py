"""bench/report.py writes a PERFORMANCE.md, with figures, from result files: the results the
benchmarks last wrote (bench/results, as shapes of what each bench produces) and small
synthetic ones for the done-when targets, into a temporary docs directory."""

from __future__ import annotations

import datetime as dt
import json
import re
import shutil
from pathlib import Path
from typing import Any

import pytest

from bench import report
from bench._results import RESULTS_DIR

NOW = dt.datetime.now(dt.UTC).replace(microsecond=0)
STAMP = NOW.isoformat().replace("+00:00", "Z")
EARLIER = (NOW - dt.timedelta(days=1)).isoformat().replace("+00:00", "Z")
MACHINE = {"cpus": 2, "python": "3.11", "platform": "Linux", "load_average_after": [0.5] * 3}


def _write(directory: Path, name: str, result: dict[str, Any]) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    (directory / f"{name}.json").write_text(json.dumps(result))


def _command_latency(ratio: float) -> dict[str, Any]:
    def summary(median: float) -> dict[str, float]:
        return {"median_ms": median, "p90_ms": median * 1.2, "min_ms": median * 0.8,
                "max_ms": median * 2}

    return {"count": 3, "skyhelm_arm_wall": summary(ratio), "skyhelm_arm_elapsed_ms": summary(
        ratio), "mavsdk_arm_wall": summary(1.0), "median_ratio_skyhelm_over_mavsdk": ratio,
        "goal_met": ratio <= 1, "samples_ms": {"skyhelm": [ratio * 0.9, ratio, ratio * 1.5],
                                               "mavsdk": [0.9, 1.0, 1.5]},
        "machine": MACHINE, "written_at": STAMP}


def _images(markdown: str) -> list[str]:
    return re.findall(r"!\[[^\]]*\]\(([^)]+)\)", markdown)


@pytest.fixture(scope="module")
def full_report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str], set[str]]:
    """Every bench's last results, stamped as written in this run, rendered once."""
    results = tmp_path_factory.mktemp("results")
    docs = tmp_path_factory.mktemp("docs")
    present = set()
    for path in RESULTS_DIR.glob("*.json"):
        if path.stem in report.bench_names():
            result = json.loads(path.read_text())
            result["written_at"] = STAMP
            _write(results, path.stem, result)
            present.add(path.stem)
    out, failed = report.write_report(results, docs, since=NOW - dt.timedelta(minutes=1))
    return out, failed, present


def test_every_bench_with_a_result_renders_its_section(
        full_report: tuple[Path, list[str], set[str]]) -> None:
    out, failed, present = full_report
    assert failed == []
    text = out.read_text()
    assert text.startswith("# Performance\n")
    for heading in ("## The machine", "## Done-when targets (issue 14)", "## This run"):
        assert heading in text
    assert f"| CPUs | {report.machine_now()['cpus']} × " in text
    # a result there is never reads as not measured; each bench appears once
    sections = text.split("\n## ")[1:]
    assert len(sections) >= len(report.bench_names())
    assert {"command_latency", "state_encode", "physics_step"} <= present
    for name in present:
        body = next(s for s in sections if f"`bench/{name}.py`" in s)
        assert report.NOT_MEASURED not in body, name


def test_figures_are_written_beside_the_document(
        full_report: tuple[Path, list[str], set[str]]) -> None:
    out, _, _ = full_report
    images = _images(out.read_text())
    assert "img/perf/command_latency.png" in images
    for image in images:
        png = out.parent / image
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", image


def test_targets_read_pass_fail_or_not_measured(tmp_path: Path) -> None:
    results = tmp_path / "results"
    _write(results, "command_latency", _command_latency(1.6))
    _write(results, "api_load", {"telemetry_clients": 100, "telemetry_latency_p99_ms": 12.0,
                                 "server_cpu_share_of_one_core": 0.3, "written_at": STAMP})
    out, _ = report.write_report(results, tmp_path / "docs", since=NOW,
                                 names=["command_latency", "api_load"])
    rows = {line.split(" | ")[0]: line for line in out.read_text().splitlines()
            if line.startswith("| ") and line.count(" | ") == 3}
    command = next(v for k, v in rows.items() if "Command round trip" in k)
    assert "SkyHelm / MAVSDK = 1.60" in command
    assert "**FAIL**" in command
    clients = next(v for k, v in rows.items() if "100 WS telemetry clients" in k)
    assert "p99 12.0 ms (0.60 × the limit)" in clients
    assert "| pass |" in clients
    vehicles = next(v for k, v in rows.items() if "50 vehicles" in k)
    assert report.NOT_MEASURED in vehicles


def test_targets_from_the_issue_benches(tmp_path: Path) -> None:
    """The shapes stream_vs_mavsdk, ws_clients and many_vehicles write."""
    results = tmp_path / "results"
    _write(results, "stream_vs_mavsdk", {
        "goal": {"variant": "thread", "skyhelm_50hz_loaded_p99_abs_error_ms": 2.0,
                 "mavsdk_20hz_loaded_p99_abs_error_ms": 4.0, "no_gap_over_100ms": True},
        "phases": [{"variant": "thread", "load": "idle", "skyhelm": {"interval_max_ms": 21.0}},
                   {"variant": "thread", "load": "loaded",
                    "skyhelm": {"interval_max_ms": 31.0}}],
        "written_at": STAMP})
    _write(results, "ws_clients", {"rows": [
        {"clients": 1, "probe_latency": {"p99_ms": 1.0}, "server_cpu_share_of_one_core": 0.01},
        {"clients": 100, "probe_latency": {"p99_ms": 25.0}, "latency": {"p99_ms": 40.0},
         "server_cpu_share_of_one_core": 0.2}], "written_at": STAMP})
    _write(results, "many_vehicles", {"rows": [
        {"vehicles": 50, "streams_silent": ["27", "32"], "stream_p99_error_ms_worst": None,
         "stream_max_gap_ms": None, "page_live": True}], "written_at": STAMP})
    out, _ = report.write_report(results, tmp_path / "docs", since=NOW,
                                 names=["stream_vs_mavsdk", "ws_clients", "many_vehicles"])
    text = out.read_text()
    assert ("SkyHelm 2.0 ms vs MAVSDK 4.0 ms (ratio 0.50); largest gap 31.0 ms | pass | "
            "`stream_vs_mavsdk`") in text
    assert "p99 25.0 ms (1.25 × the limit), server 20% of a core | **FAIL** |" in text
    assert ("worst p99 error ?, largest gap ?, 2 streams silent, page live | **FAIL** |"
            in text)


def test_a_missing_or_older_result_is_not_measured_in_this_run(tmp_path: Path) -> None:
    results = tmp_path / "results"
    old = _command_latency(0.5)
    old["written_at"] = EARLIER
    _write(results, "command_latency", old)
    out, failed = report.write_report(results, tmp_path / "docs", since=NOW,
                                      names=["command_latency", "state_encode"])
    assert failed == []
    text = out.read_text()
    assert "command_latency.json is from an earlier run" in text
    encode = text.split("## ")[-1]
    assert report.NOT_MEASURED in encode
    assert _images(text) == []

    # without --since every result counts, whenever it was written
    out, _ = report.write_report(results, tmp_path / "docs2", names=["command_latency"])
    assert "SkyHelm's arm round trip takes **0.50×** MAVSDK's" in out.read_text()
    assert (tmp_path / "docs2" / "img" / "perf" / "command_latency.png").exists()


def test_a_failing_report_is_named_and_the_document_still_written(tmp_path: Path) -> None:
    results = tmp_path / "results"
    broken = _command_latency(0.5)
    del broken["mavsdk_arm_wall"]
    _write(results, "command_latency", broken)
    out, failed = report.write_report(results, tmp_path / "docs", names=["command_latency"])
    assert failed == ["command_latency"]
    assert "The report of this benchmark failed" in out.read_text()
    shutil.rmtree(tmp_path / "docs")
