"""Browser fixtures: Debian's Chromium driven by Playwright; skipped when it is missing."""

from __future__ import annotations

import functools
from collections.abc import Callable, Generator, Iterator
from typing import Any

import httpx
import pytest
from playwright.sync_api import Frame, Page

from .flows import open_dashboard
from .harness import Serve, SharedChromium, shared_chromium_context
from .sharing import FAMILY_OF

# Playwright's wait_for_function polls on every animation frame unless told otherwise, and a
# wait that asks for every frame keeps a software-rendered page drawing: measured on a landed
# quad's page, 3 % of a core idle, 9.4 % while such a wait is pending, 5.4 % polling every
# 20 ms. The browser tests wait at that interval unless one asks for frames ("raf").
WAIT_POLLING_MS = 20.0


def _polling_every_interval(wait: Callable[..., Any]) -> Callable[..., Any]:
    @functools.wraps(wait)
    def waiting(self: Any, expression: str, *, polling: Any = None, **options: Any) -> Any:
        return wait(self, expression, polling=WAIT_POLLING_MS if polling is None else polling,
                    **options)

    return waiting


Page.wait_for_function = _polling_every_interval(Page.wait_for_function)  # type: ignore[method-assign]
Frame.wait_for_function = _polling_every_interval(Frame.wait_for_function)  # type: ignore[method-assign]

# Chromium for the browser modules one worker runs one after another (one per set of
# arguments), closed when the worker goes on to other tests or ends.
SHARED_CHROMIUM = SharedChromium()


class _SharedServe:
    """The running server of one family of tests/browser/sharing.py."""

    def __init__(self) -> None:
        self.key: tuple[str, tuple[str, ...]] | None = None
        self.server: Serve | None = None

    def get(self, family: str, args: list[str]) -> Serve:
        key = (family, tuple(args))
        server = self.server
        if key != self.key or server is None or server._process is None \
                or server._process.poll() is not None:
            self.close()
            server = Serve(extra_args=list(args))
            server.start()
            self.key, self.server = key, server
        return server

    def close(self) -> None:
        server, self.server, self.key = self.server, None, None
        if server is not None:
            server.stop()
            server.discard_log()


SHARED_SERVE = _SharedServe()


def _family(item: pytest.Item | None) -> str | None:
    return None if item is None else FAMILY_OF.get(item.nodeid.split("::", 1)[0])


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if "tests/browser" in str(item.fspath):
            item.add_marker(pytest.mark.browser)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    yield
    if nextitem is None or "tests/browser" not in str(nextitem.fspath):
        SHARED_CHROMIUM.close()
    if _family(nextitem) is None or _family(nextitem) != _family(item):
        SHARED_SERVE.close()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Generator[None, Any, None]:
    """A failed browser test (or its set-up) reports what its pages logged (the page's own
    log panel) and the last lines its server wrote."""
    outcome = yield
    report = outcome.get_result()
    if call.when not in ("setup", "call") or not report.failed:
        return
    funcargs = getattr(item, "funcargs", {})
    serve = funcargs.get("serve")
    if isinstance(serve, Serve):
        report.sections.append(("server log", serve.log_tail(60)))
    for name in ("page", "second_page", "scene_page"):
        page = funcargs.get(name)
        if page is None or page.is_closed():
            continue
        try:
            text = page.inner_text("#log", timeout=2_000)
        except Exception as exc:  # a report about a broken page must still be made
            text = f"(no log: {exc})"
        report.sections.append((f"{name} log", text))


@pytest.fixture(scope="module")
def browser(request: pytest.FixtureRequest) -> Iterator[Any]:
    """Chromium; it ignores the server's Content-Security-Policy (which forbids the eval that
    Playwright's string predicates use) unless the module sets ENFORCE_CSP (test_csp.py).
    A module's BROWSER_ARGS add to Chromium's arguments, its VIEWPORT sets the window."""
    with shared_chromium_context(
        SHARED_CHROMIUM,
        bypass_csp=not getattr(request.module, "ENFORCE_CSP", False),
        extra_args=getattr(request.module, "BROWSER_ARGS", ()),
        viewport=getattr(request.module, "VIEWPORT", None),
    ) as context:
        yield context


@pytest.fixture(scope="module")
def chromium() -> Any:
    """The worker's shared Chromium itself, with no context: each test opens its own (its
    size and colour scheme)."""
    return SHARED_CHROMIUM.browser()


@pytest.fixture(scope="module")
def serve(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Serve]:
    """One `skyhelm serve` per test module, with the module's SERVE_ARGS (a list, or a
    function of a fresh directory that gives the list: files the server is to read), or the
    one its family shares (tests/browser/sharing.py)."""
    args = getattr(request.module, "SERVE_ARGS", [])
    if callable(args):
        args = args(tmp_path_factory.mktemp("serve"))
    family = FAMILY_OF.get(request.node.nodeid.split("::", 1)[0])
    if family is not None:  # stopped when the worker goes on to another family (above)
        yield SHARED_SERVE.get(family, list(args))
        return
    with Serve(extra_args=list(args)).running() as server:
        yield server


@pytest.fixture(scope="module")
def api(serve: Serve) -> Iterator[httpx.Client]:
    with serve.client() as client:
        yield client


def _dashboard(browser: Any, serve: Serve) -> Iterator[Any]:
    """A fresh dashboard page for one test (without the scene, which software WebGL makes
    slow), closed after it."""
    page = open_dashboard(browser, serve.url, scene=False)
    try:
        yield page
    finally:
        if not page.is_closed():
            page.close()


@pytest.fixture
def page(browser: Any, serve: Serve) -> Iterator[Any]:
    yield from _dashboard(browser, serve)


@pytest.fixture
def second_page(browser: Any, serve: Serve) -> Iterator[Any]:
    """Another tab of the same browser, beside `page`."""
    yield from _dashboard(browser, serve)
