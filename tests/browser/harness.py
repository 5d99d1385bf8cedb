"""Running `skyhelm serve` (with its simulated vehicle) and a headless Chromium for the
browser tests and the screenshot script."""

from __future__ import annotations

import asyncio
import contextlib
import functools
import os
import re
import secrets
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import httpx

from skyhelm_client.tls import default_tls
from tests.browser.ordinary_priority import ORDINARY_PRIORITY
from tests.waiting import wait_for_blocking as wait_for

CHROMIUM = Path("/usr/bin/chromium")
# What the tests start: Chromium at the priority of everything else, its feature switches
# merged with Playwright's (the script says why).
CHROMIUM_FOR_TESTS = Path(__file__).with_name("chromium_for_tests.sh")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--disable-quic",
]
READY = re.compile(r"SkyHelm ready: (http://\S+)")
REPO = Path(__file__).resolve().parents[2]
# Headless Chromium is the whole browser: each page opens in a window of its own, whose
# address bar loads the omnibox popup and its AI mode panel as web pages of their own
# (chrome://omnibox-popup.top-chrome) in a renderer beside the page's. Measured on the
# cockpit (10 opens of a landed quad's page, CPU of every process): 36.7 CPU-s with them,
# 22.1 without, 21.3 s of wall time against 14.2. The tests never use the address bar.
# Added to Playwright's list by chromium_for_tests.sh, which only the tests start (given to
# Chromium alone, the switch would replace Playwright's).
CHROMIUM_TEST_ARGS = [*CHROMIUM_ARGS, "--disable-features=WebUIOmniboxPopup,WebUIOmniboxAimPopup"]


def chromium_executable() -> str:
    """Chromium for a test, through the script that merges its feature switches and, as
    root, keeps it from raising its priority."""
    return str(CHROMIUM_FOR_TESTS)


def skyhelm_command() -> list[str]:
    """`skyhelm` as installed next to this interpreter, or the same CLI by module."""
    script = Path(sys.executable).with_name("skyhelm")
    return [str(script)] if script.exists() else [sys.executable, "-m", "server.cli"]


@dataclass
class Serve:
    """One `skyhelm serve --port 0` process; restartable on the same port and token."""

    extra_args: list[str] = field(default_factory=list)
    token: str = field(default_factory=lambda: secrets.token_urlsafe(16))
    url: str = ""
    port: int = 0
    _process: subprocess.Popen[str] | None = None
    _log: Any = None

    @property
    def base(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout_s: float = 60.0) -> str:
        self.discard_log()
        # The file outlives this call: it is the server's stderr until stop().
        self._log = tempfile.NamedTemporaryFile(  # noqa: SIM115
            "w+", prefix="skyhelm-serve-", suffix=".log", delete=False
        )
        args = [*skyhelm_command(), "serve", "--port", str(self.port), f"--token={self.token}",
                "--no-tlog", *self.extra_args]
        self._process = subprocess.Popen(
            args, cwd=REPO, stdout=subprocess.PIPE, stderr=self._log, text=True,
            stdin=subprocess.DEVNULL, start_new_session=True,
        )
        found: list[str] = []

        def read_stdout() -> None:
            assert self._process is not None
            assert self._process.stdout is not None
            for line in self._process.stdout:
                match = READY.search(line)
                if match and not found:
                    found.append(match.group(1))

        threading.Thread(target=read_stdout, daemon=True).start()
        process = self._process
        with contextlib.suppress(AssertionError):  # a timeout is reported below, with the log
            wait_for("the ready line", lambda: found or process.poll() is not None, timeout_s,
                     every_s=0.05)  # fmt: skip
        if not found:
            self.stop()
            raise RuntimeError(f"skyhelm serve did not start:\n{self.log_tail()}")
        self.url = found[0]
        self.port = urlsplit(self.url).port or 0
        return self.url

    def stop(self) -> None:
        process, self._process = self._process, None
        if process is None or process.poll() is not None:
            return
        process.send_signal(signal.SIGINT)
        try:
            process.wait(15.0)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(5.0)

    def discard_log(self) -> None:
        """Remove the server's stderr file (kept after stop() for log_tail())."""
        log, self._log = self._log, None
        if log is not None:
            log.close()
            with contextlib.suppress(FileNotFoundError):
                os.unlink(log.name)

    def restart(self) -> str:
        """Same port and token, so an open page can find the server again."""
        self.stop()

        def started() -> str | None:
            try:
                return self.start()
            except RuntimeError:  # the old process's port may not be free yet
                return None

        url: str = wait_for("skyhelm serve on its old port", started, 30.0, every_s=0.5)
        return url

    def log_tail(self, lines: int = 40) -> str:
        if self._log is None:
            return ""
        self._log.flush()
        text = Path(self._log.name).read_text(errors="replace")
        return "\n".join(text.splitlines()[-lines:])

    @contextlib.contextmanager
    def running(self) -> Iterator[Serve]:
        """Started for the block, stopped (its log removed) after it."""
        self.start()
        try:
            yield self
        finally:
            self.stop()
            self.discard_log()

    def client(self) -> ServeClient:
        return ServeClient(self, base_url=f"{self.base}/api/v1", timeout=10.0,
                           headers={"Authorization": f"Bearer {self.token}"},
                           verify=default_tls())


class ServeClient(httpx.Client):
    """A client of one `skyhelm serve`'s API that knows its server (whose simulated vehicle
    a set-up flight fast-forwards: tests/browser/pausing.py)."""

    def __init__(self, serve: Serve, **options: Any) -> None:
        super().__init__(**options)
        self.serve = serve


def vehicle_state(api: httpx.Client, vehicle_id: int = 1) -> dict[str, Any]:
    response = api.get(f"/vehicles/{vehicle_id}")
    response.raise_for_status()
    state: dict[str, Any] = response.json()
    return state


def altitude_m(state: dict[str, Any]) -> float:
    glob = state.get("global") or {}
    if glob.get("alt_rel_m") is not None:
        return float(glob["alt_rel_m"])
    home_down = (state.get("home") or {}).get("down_m") or 0.0
    return float(home_down - state["position_ned"]["down_m"])


def speed_m_s(state: dict[str, Any]) -> float:
    v = state["velocity_ned"]
    return float((v["north_m_s"] ** 2 + v["east_m_s"] ** 2 + v["down_m_s"] ** 2) ** 0.5)


@contextlib.contextmanager
def empty_scene() -> Iterator[tuple[str, str]]:
    """A scene hub with no vehicle behind its own tiny app: the reference 'empty' picture."""
    from fastapi import FastAPI

    from server.scene.hub import SceneHub
    from tests.serving import uvicorn_serving

    token = secrets.token_urlsafe(12)
    ready = threading.Event()
    holder: dict[str, Any] = {}

    async def run() -> None:
        hub = SceneHub()
        app = FastAPI()
        hub.mount(app, check_token=lambda t: t == token)
        await hub.start()
        stop = asyncio.Event()
        holder["stop"] = functools.partial(asyncio.get_running_loop().call_soon_threadsafe,
                                           stop.set)  # fmt: skip
        try:
            async with uvicorn_serving(app) as host:
                holder["host"] = host
                ready.set()
                await stop.wait()
        finally:
            await hub.stop()

    thread = threading.Thread(target=lambda: asyncio.run(run()), daemon=True)
    thread.start()
    if not ready.wait(20.0):
        raise RuntimeError("empty scene server did not start")
    try:
        yield f"http://{holder['host']}", token
    finally:
        holder["stop"]()
        thread.join(10.0)


@contextlib.contextmanager
def chromium_context(
    bypass_csp: bool = True,
    extra_args: Sequence[str] = (),
    viewport: dict[str, int] | None = None,
) -> Iterator[Any]:
    """Debian's Chromium under Playwright, in a fresh profile (a skip when either is
    missing); it ignores the server's Content-Security-Policy (which forbids the eval that
    Playwright's string predicates use) unless told not to. `extra_args` add to Chromium's
    arguments; `viewport` sets the window (1600×1000 by default). The context's
    `profile_dir` names its profile (Chromium's processes carry it on their command line).
    A SharedChromium's running Playwright drives it, if there is one (Playwright's sync API
    runs one at a time in a thread)."""
    import pytest

    if not CHROMIUM.exists():
        pytest.skip("/usr/bin/chromium is not installed (make chromium, as root)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    with (
        tempfile.TemporaryDirectory(prefix="skyhelm-chromium-") as profile,
        contextlib.ExitStack() as stack,
        ORDINARY_PRIORITY.held(),
    ):
        playwright = _RUNNING_PLAYWRIGHT.get("sync") or stack.enter_context(
            sync_api.sync_playwright()
        )
        context = playwright.chromium.launch_persistent_context(
            profile,
            executable_path=chromium_executable(),
            args=[*CHROMIUM_TEST_ARGS, *extra_args],
            headless=True,
            viewport=viewport or {"width": 1600, "height": 1000},
            bypass_csp=bypass_csp,
        )
        context.profile_dir = profile
        try:
            yield context
        finally:
            context.close()


# The Playwright a SharedChromium keeps running in this process, while it does.
_RUNNING_PLAYWRIGHT: dict[str, Any] = {}


class SharedChromium:
    """One Chromium per set of arguments for a run of browser modules on one worker: launching
    it costs a second of CPU, a fresh context per module (its own cookies, storage and
    settings) costs little. Closed when the worker leaves the browser modules."""

    def __init__(self) -> None:
        self._playwright: Any = None
        self._manager: Any = None
        self._browsers: dict[tuple[str, ...], Any] = {}
        self._priority = contextlib.ExitStack()

    def browser(self, extra_args: Sequence[str] = ()) -> Any:
        import pytest

        if not CHROMIUM.exists():
            pytest.skip("/usr/bin/chromium is not installed (make chromium, as root)")
        sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
        if self._playwright is None:
            self._manager = sync_api.sync_playwright()
            self._playwright = self._manager.__enter__()
            _RUNNING_PLAYWRIGHT["sync"] = self._playwright
            self._priority.enter_context(ORDINARY_PRIORITY.held())
        key = tuple(extra_args)
        browser = self._browsers.get(key)
        if browser is None or not browser.is_connected():
            browser = self._playwright.chromium.launch(
                executable_path=chromium_executable(), args=[*CHROMIUM_TEST_ARGS, *extra_args],
                headless=True,
            )
            self._browsers[key] = browser
        return browser

    def close(self) -> None:
        browsers, self._browsers = self._browsers, {}
        for browser in browsers.values():
            with contextlib.suppress(Exception):  # a crashed browser is gone already
                browser.close()
        manager, self._manager, self._playwright = self._manager, None, None
        _RUNNING_PLAYWRIGHT.pop("sync", None)
        if manager is not None:
            manager.__exit__(None, None, None)
        self._priority.close()


@contextlib.contextmanager
def shared_chromium_context(
    shared: SharedChromium,
    bypass_csp: bool = True,
    extra_args: Sequence[str] = (),
    viewport: dict[str, int] | None = None,
) -> Iterator[Any]:
    """A fresh context of the shared Chromium, as chromium_context() gives one."""
    context = shared.browser(extra_args).new_context(
        viewport=viewport or {"width": 1600, "height": 1000}, bypass_csp=bypass_csp
    )
    try:
        yield context
    finally:
        context.close()
