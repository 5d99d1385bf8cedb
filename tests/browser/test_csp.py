"""The page and the 3D scene under the server's Content-Security-Policy, in Chromium: both
work (telemetry shows, control can be taken, the scene draws through its socket) with no
CSP violation in either document; the token leaves the URL at load, lives in sessionStorage
and an HttpOnly cookie the page's scripts cannot read, and no request after the first
carries it in its URL."""

from __future__ import annotations

from typing import Any

import httpx

from .flows import SCENE_START_MS
from .harness import Serve, wait_for

SERVE_ARGS = ["--sim-speed", "2"]
# The browser fixture honours the CSP here; every predicate below is a function, which
# Playwright compiles without the page's eval (string predicates would be refused).
ENFORCE_CSP = True

# Runs in every frame before its scripts: collects the violations the document reports.
RECORD_VIOLATIONS = """
window.__csp = [];
document.addEventListener("securitypolicyviolation", (e) => {
  window.__csp.push(`${e.violatedDirective} ${e.blockedURI} ${e.sourceFile}:${e.lineNumber}`);
});
"""


def test_page_and_scene_work_under_the_csp_and_the_token_leaves_the_url(
    browser: Any, serve: Serve
) -> None:
    console: list[str] = []
    requests: list[str] = []
    page = None
    bearer = {"Authorization": f"Bearer {serve.token}"}
    try:
        page = browser.new_page()
        page.on("console", lambda m: console.append(f"{m.type}: {m.text}"))
        page.on("request", lambda r: requests.append(r.url))
        page.add_init_script(RECORD_VIOLATIONS)
        page.goto(serve.url)
        page.wait_for_function(
            "() => document.getElementById('mode').textContent !== '–'", timeout=SCENE_START_MS
        )
        page.wait_for_function(
            "() => document.getElementById('conn-status').textContent === 'connected'",
            timeout=30_000,
        )
        canvas = page.frame_locator("#scene").locator("canvas").first
        canvas.wait_for(timeout=SCENE_START_MS)
        scene = page.frame(url=lambda url: "/scene/" in url)
        assert scene is not None
        # the viser client, under its CSP, reached viser through the proxied socket
        status = wait_for(
            "the viser client connected through the proxy",
            lambda: (
                (s := httpx.get(f"{serve.base}/scene/api/status", headers=bearer).json())[
                    "proxied_sockets"
                ]
                >= 1
                and s["viser_clients"] >= 1
                and s
            ),
            30.0,
        )
        assert status["vehicles"] == [1]
        assert "token=" not in page.url
        assert page.evaluate("sessionStorage.getItem('skyhelm.token')") == serve.token
        assert "skyhelm_token" not in page.evaluate("document.cookie")  # HttpOnly
        assert page.evaluate("window.__csp") == []
        assert scene.evaluate("window.__csp") == []
        refused = [line for line in console if "Content Security Policy" in line]
        assert not refused, refused
        later = [url for url in requests[1:] if serve.token in url]
        assert not later, later

    finally:
        if page is not None:
            page.close()


def test_control_and_a_reload_work_under_the_csp(browser: Any, serve: Serve) -> None:
    """Without the scene (software WebGL would hold the page's thread): the control socket,
    in its worker, rides the cookie; a reload finds the token in sessionStorage."""
    page = browser.new_page()
    try:
        page.add_init_script(RECORD_VIOLATIONS)
        page.goto(f"{serve.url}&scene=off")
        for _ in range(2):
            page.wait_for_function(
                "() => document.getElementById('conn-status').textContent === 'connected'",
                timeout=30_000,
            )
            assert "token=" not in page.url
            assert "scene=off" in page.url
            page.click("#take-control")
            page.wait_for_function(
                "() => document.getElementById('holder').textContent.startsWith('you')",
                timeout=20_000,
            )
            page.click("#release")
            page.wait_for_function(
                "() => !document.getElementById('holder').textContent.startsWith('you')",
                timeout=20_000,
            )
            assert page.evaluate("window.__csp") == []
            page.reload()
        headers = page.evaluate(
            """async () => {
                const r = await fetch('/api/v1/health');
                return Object.fromEntries([...r.headers.entries()]);
            }"""
        )
        assert headers["x-content-type-options"] == "nosniff"
        assert "frame-ancestors 'self'" in headers["content-security-policy"]
        assert headers["referrer-policy"] == "no-referrer"
    finally:
        page.close()
