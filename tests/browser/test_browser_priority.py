"""The browser of the tests runs at the priority of the servers and vehicles beside it: run
as root, Chromium would raise its display threads to nice -8 and, rendering WebGL in
software, take the cores from the other workers' vehicles under test; kept from that, it
could not undo its own lowering of each renderer to nice 5 (tests/browser/ordinary_priority.py),
and every page ran behind everything else on a busy machine."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests.browser.harness import chromium_context
from tests.browser.ordinary_priority import nice_of_threads
from tests.waiting import wait_for_blocking as wait_for

WEBGL_PAGE = ("<canvas id=c></canvas>"
              "<script>c.getContext('webgl').clearColor(0, 0, 0, 1)</script>")


def _niceness_of_threads(profile: str) -> dict[int, int]:
    """Each thread's nice value, of every process started with this profile."""
    flag = f"--user-data-dir={profile}".encode()
    found: dict[int, int] = {}
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            if flag not in (proc / "cmdline").read_bytes():
                continue
        except OSError:  # gone meanwhile
            continue
        found.update(nice_of_threads(int(proc.name)))
    return found


def test_the_tests_chromium_raises_no_thread_above_ordinary_priority() -> None:
    if os.geteuid() != 0:
        pytest.skip("only root may raise priorities: nothing to keep Chromium from")
    with chromium_context() as context:
        context.new_page().set_content(WEBGL_PAGE)
        # the browser, its GPU process and a renderer: Chromium sets priorities as each starts
        threads = wait_for(
            "Chromium's processes", lambda: (
                found if len(found := _niceness_of_threads(context.profile_dir)) > 40 else None),
            20.0)  # fmt: skip
    raised = {tid: nice for tid, nice in threads.items() if nice < 0}
    assert not raised, f"{len(raised)} of {len(threads)} threads above ordinary priority"


def test_the_tests_chromium_runs_no_page_below_ordinary_priority() -> None:
    if os.geteuid() != 0:
        pytest.skip("only root may raise priorities back: nothing to keep Chromium at")
    with chromium_context() as context:
        page = context.new_page()
        page.set_content(WEBGL_PAGE)
        second = context.new_page()  # a renderer started after the first
        second.set_content("<p>a second page</p>")
        # Chromium starts a renderer at nice 5; within a poll it runs at 0 like the rest
        wait_for(
            "every thread of the browser at nice 0",
            lambda: (
                len(found := _niceness_of_threads(context.profile_dir)) > 40
                and set(found.values()) == {0}
            ),
            10.0,
        )
