"""What each test costs the machine: CPU seconds of the test's process and every process it
started (servers, simulated vehicles, Chromium), with its wall time; one JSON line per test
in ``$SKYHELM_TEST_CPU_LOG.<worker>``. Read with ``python -m tests.cpu_account LOG...``.
A failed or erring test is also written whole, as it happens, to
``$SKYHELM_TEST_CPU_LOG.<worker>.failures`` (a run that is stopped before its summary, or one
watched while it runs, still says what failed and why).

A process's CPU is counted while it lives (/proc/<pid>/stat) and, once its parent reaped it,
in the parent's children's time: a test is charged what its processes used between its
setup and its teardown; a module fixture's processes are charged to the tests that ran
while they lived. A process whose parent ended before reaping it goes to init, and its time
with it: Chromium's renderers when a browser closes, so the test that closed one can show
less, even negative, CPU (read a browser module's figure as a lower bound).
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path

import pytest

_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


def proc_stat(pid: int) -> tuple[str, list[str]] | None:
    """A process's name and the fields of /proc/<pid>/stat after it (the state first), or
    None once it has ended."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat[stat.index("(") + 1:stat.rindex(")")], stat[stat.rindex(")") + 2:].split()


def children_of() -> dict[int, list[int]]:
    """Each live process's children, by parent pid (/proc)."""
    children: dict[int, list[int]] = defaultdict(list)
    for entry in os.scandir("/proc"):
        if entry.name.isdigit() and (found := proc_stat(int(entry.name))) is not None:
            children[int(found[1][1])].append(int(entry.name))
    return children


def _process_s(pid: int) -> float:
    found = proc_stat(pid)
    if found is None:
        return 0.0
    # utime, stime, cutime, cstime: fields 14-17 of proc(5), counted from the state (3)
    return sum(int(found[1][i]) for i in range(11, 15)) * _TICK_S


def tree_cpu_s() -> float:
    """CPU seconds of this process, its reaped children and every live descendant."""
    own = os.times()
    total = own.user + own.system + own.children_user + own.children_system
    children = children_of()
    stack = list(children.get(os.getpid(), []))
    while stack:
        pid = stack.pop()
        total += _process_s(pid)
        stack.extend(children.get(pid, []))
    return total


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item) -> Iterator[None]:
    log = os.environ.get("SKYHELM_TEST_CPU_LOG")
    if not log:
        yield
        return
    cpu0, wall0 = tree_cpu_s(), time.monotonic()
    yield
    line = {"test": item.nodeid, "cpu_s": round(tree_cpu_s() - cpu0, 3),
            "wall_s": round(time.monotonic() - wall0, 3)}
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    with open(f"{log}.{worker}", "a", encoding="utf-8") as out:
        out.write(json.dumps(line) + "\n")


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    log = os.environ.get("SKYHELM_TEST_CPU_LOG")
    if not log or not report.failed:
        return
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    when = time.strftime("%H:%M:%S")
    with open(f"{log}.{worker}.failures", "a", encoding="utf-8") as out:
        out.write(f"=== {when} {report.nodeid} ({report.when})\n{report.longreprtext}\n")


def main(paths: list[str]) -> None:
    modules: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0, 0])
    for path in paths:
        if path.endswith(".failures"):  # what failed, not what it cost
            continue
        for raw in Path(path).read_text().splitlines():
            line = json.loads(raw)
            row = modules[line["test"].split("::", 1)[0]]
            row[0] += line["cpu_s"]
            row[1] += line["wall_s"]
            row[2] += 1
    total = sum(row[0] for row in modules.values())
    print(f"{'module':70} {'cpu_s':>8} {'wall_s':>8} {'tests':>5}")
    for module, (cpu_s, wall_s, count) in sorted(modules.items(), key=lambda kv: -kv[1][0]):
        print(f"{module:70} {cpu_s:8.1f} {wall_s:8.1f} {int(count):5}")
    print(f"{'total':70} {total:8.1f}")


if __name__ == "__main__":
    main(sys.argv[1:])
