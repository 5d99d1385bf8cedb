"""The documented flows, one after another against one server, as a new user runs them: the
curl sessions taken from README.md and docs/api.md as they stand (only the URL line
replaced), the examples as `python examples/x.py URL` runs them (on the runtime
dependencies only), a flight from the page in Chromium, and scripts killed half-way. After
each, the vehicle is on the ground disarmed (or, after a killed script, holding in the air)
and nobody holds control: the next flow never needs `force`.

Shared by the chain on the simulated vehicle (tests/client, tests/browser) and on real PX4
SITL (tests/px4)."""

from __future__ import annotations

import contextlib
import importlib.metadata
import json
import math
import os
import re
import select
import signal
import subprocess
import sys
import threading
import time
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
from packaging.requirements import Requirement

from skyhelm_client.tls import default_tls
from tests.waiting import wait_for_blocking

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
API_DOC = ROOT / "docs" / "api.md"
URL_LINE = re.compile(r"^URL='[^']*'.*$", re.MULTILINE)
FLIGHT_TIMEOUT_S = 400.0
LEG_M = 10.0  # the curl sessions' leg north
LEG_FLOWN = re.compile(r"leg flown: (-?[\d.]+) m north of its start")

# Runs an example as `python examples/x.py URL` would, with every module of a distribution
# outside the runtime dependencies hidden, as in the environment `make run` creates.
# Ctrl-C raises KeyboardInterrupt, as in a terminal, even where the test runs as a
# background job whose shell left SIGINT ignored.
_RUNNER = """
import json, runpy, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)
path, hidden = sys.argv[1], set(json.loads(sys.argv[2]))
sys.argv = [path, *sys.argv[3:]]

class Hidden:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in hidden:
            raise ModuleNotFoundError(f"No module named {name!r} (not installed by make run)")
        return None

sys.meta_path.insert(0, Hidden())
runpy.run_path(path, run_name="__main__")
"""


def doc_block(doc: Path, language: str, needle: str) -> str:
    """The document's first ```language block that contains needle."""
    for block in re.findall(rf"```{language}\n(.*?)```", doc.read_text(), re.DOTALL):
        if needle in block:
            return str(block)
    raise AssertionError(f"{doc.name} has no {language} block with {needle!r}")


def curl_session(doc: Path, url: str) -> str:
    """The document's curl session with its URL line replaced by ``url``."""
    return URL_LINE.sub(f"URL='{url}'", doc_block(doc, "sh", "URL='"), count=1)


def _normalised(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def runtime_distributions() -> set[str]:
    """The distributions `pip install .` brings: pyproject's [project] dependencies and,
    recursively, theirs (extras left out)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    found = {_normalised(project["name"])}
    todo = [Requirement(text) for text in project["dependencies"]]
    while todo:
        requirement = todo.pop()
        name = _normalised(requirement.name)
        if name in found:
            continue
        if requirement.marker is not None and not requirement.marker.evaluate({"extra": ""}):
            continue
        found.add(name)
        try:
            todo += [Requirement(text) for text in importlib.metadata.requires(name) or []]
        except importlib.metadata.PackageNotFoundError:
            continue
    return found


def modules_not_installed_by_make_run() -> set[str]:
    """Top-level modules installed here that `pip install .` would not bring."""
    runtime = runtime_distributions()
    return {
        module
        for module, owners in importlib.metadata.packages_distributions().items()
        if not any(_normalised(owner) in runtime for owner in owners)
    }


@dataclass
class Chain:
    """One server and its vehicle, and the flows run against it in turn."""

    base_url: str  # http://127.0.0.1:<port>
    token: str
    workdir: Path
    vehicle: int = 1
    flows: int = 0
    server_log: Path | None = None  # its tail goes with a failed flow's output

    @property
    def url(self) -> str:
        """What `skyhelm serve` printed: the URL a script is given."""
        return f"{self.base_url}/?token={self.token}"

    def client(self) -> httpx.Client:
        return httpx.Client(
            base_url=f"{self.base_url}/api/v1",
            headers={"Authorization": f"Bearer {self.token}"},
            timeout=30.0,
            verify=default_tls(),
        )

    def state(self) -> dict[str, Any]:
        return self._read("")

    def control(self) -> dict[str, Any]:
        return self._read("/control")

    def _read(self, path: str) -> dict[str, Any]:
        with self.client() as api:
            answer = api.get(f"/vehicles/{self.vehicle}{path}")
            answer.raise_for_status()
            read: dict[str, Any] = answer.json()
            return read

    # -- the flows ---------------------------------------------------------------------

    def curl_session(self, doc: Path) -> str:
        """The document's curl session in bash; it must fly to the end and land, and fly its
        leg: 10 m north of where the leg starts, whatever `position_ned` read at the start
        (a flight before may have ended away from the estimator's origin). The leg is
        measured here, from the state sampled while the session runs, not taken from the
        session's word."""
        script = curl_session(doc, self.url)
        assert self.token in script
        start_north_m = self.state()["position_ned"]["north_m"]
        with self._northmost() as northmost:
            result = subprocess.run(
                ["bash", "-c", script], capture_output=True, text=True,
                timeout=FLIGHT_TIMEOUT_S, check=False,
            )  # fmt: skip
        self._log(f"curl-{doc.stem}", result.stdout + result.stderr)
        assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
        assert '"result":"ACCEPTED"' in result.stdout  # arm, takeoff, offboard, rtl
        assert '"limit":12.0' in result.stdout  # the envelope's refusal, as shown
        said = LEG_FLOWN.search(result.stdout)
        assert said is not None, result.stdout[-3000:]
        assert float(said.group(1)) >= LEG_M, said.group(0)
        flown_m = northmost[0] - start_north_m
        assert flown_m >= LEG_M - 0.5, (
            f"the leg was not flown: {flown_m:.1f} m north of {start_north_m:.1f}"
        )
        self.after_a_flight()
        return result.stdout

    @contextlib.contextmanager
    def _northmost(self) -> Iterator[list[float]]:
        """The greatest position_ned.north_m seen while the block runs (sampled at 5 Hz)."""
        seen = [-math.inf]
        done = threading.Event()

        def sample() -> None:
            with self.client() as api:
                while not done.wait(0.2):
                    try:
                        where = api.get(f"/vehicles/{self.vehicle}").json()["position_ned"]
                    except (httpx.HTTPError, KeyError, ValueError):
                        continue
                    if where and where.get("north_m") is not None:
                        seen[0] = max(seen[0], float(where["north_m"]))

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        try:
            yield seen
        finally:
            done.set()
            sampler.join(timeout=10)

    def flight_ending_away(self, north_m: float = 10.5) -> None:
        """A flight that lands ``north_m`` north of where it took off (a pilot's earlier
        flight): afterwards position_ned reads that far north on the ground, since it is
        measured from the estimator's origin, not from where a flight starts."""
        vehicle = f"/vehicles/{self.vehicle}"
        # a pilot takes off once the page reads ready to fly: a PX4 just started refuses
        # to arm until its estimator has a position ("No valid position estimate")
        wait_for_blocking("ready to fly", lambda: _armable(self.state()), 120.0, 0.5)
        with self.client() as api:
            start = self.state()["position_ned"]["north_m"]
            lease = api.post(f"{vehicle}/control", json={"client_name": "flight ending away"})
            lease.raise_for_status()
            api.headers["X-Lease-Id"] = lease.json()["lease_id"]
            try:
                _accepted(api.post(f"{vehicle}/takeoff", json={"altitude_m": 5}))
                wait_for_blocking("the take-off", lambda: _alt_rel_m(self.state()) > 4.2, 120.0)
                offset = {"north_m": north_m, "east_m": 0.0, "up_m": 0.0}
                api.post(f"{vehicle}/intents/offset", json=offset).raise_for_status()
                wait_for_blocking(
                    "the hop north",
                    lambda: self.state()["position_ned"]["north_m"] > start + north_m - 0.5,
                    120.0,
                )  # fmt: skip
                _accepted(api.post(f"{vehicle}/land"))
                wait_for_blocking("landed away", lambda: not self.state()["armed"], 180.0, 0.5)
            finally:
                api.delete(f"{vehicle}/control")
        self.after_a_flight()
        assert self.state()["position_ned"]["north_m"] > start + north_m - 1.0

    def example(self, name: str) -> str:
        """An example run to its end: the square flown, landed."""
        process = self._start_example(name)
        output, _ = process.communicate(timeout=FLIGHT_TIMEOUT_S)
        self._log(name, output)
        assert process.returncode == 0, output[-3000:] + self._server_side()
        assert output.count("at north") == 4, output[-3000:]
        assert "landed" in output
        self.after_a_flight()
        return output

    def example_killed_half_way(self, name: str, sig: signal.Signals) -> str:
        """An example stopped by ``sig`` once it flew the square's first corner; control is
        free again right after (released by the script, or its process seen gone)."""
        process = self._start_example(name)
        assert process.stdout is not None
        output = ""
        deadline = time.monotonic() + FLIGHT_TIMEOUT_S
        while "at north" not in output:
            assert time.monotonic() < deadline, f"{name} flew no corner: {output[-3000:]}"
            assert process.poll() is None, f"{name} ended before a corner: {output[-3000:]}"
            readable, _, _ = select.select([process.stdout], [], [], 0.5)
            if readable:
                output += process.stdout.readline()
        process.send_signal(sig)
        rest, _ = process.communicate(timeout=30)
        output += rest
        self._log(f"{name}-{sig.name}", output)
        assert process.returncode != 0
        control = wait_for_blocking(
            f"control free after {name} got {sig.name}",
            lambda: (c := self.control())["holder"] is None and c,
            5.0,
        )
        ended = control["last_end"]
        assert ended is not None, control
        assert ended["end"] in ("released", "gone"), control
        if sig is signal.SIGKILL:  # nothing ran in the script: the server saw it gone
            assert ended["end"] == "gone", control
        self.flows += 1
        return output

    def page_flight(self, context: Any, altitude_m: float = 5.0) -> None:
        """A pilot on the page: take control, arm, take off, offboard here, return, give
        control back; every click answered ACCEPTED by the vehicle."""
        from tests.browser import flows

        page = flows.open_dashboard(context, self.url, scene=False)
        try:
            flows.take_control(page)
            flows.click_and_wait_result(page, "#btn-arm", confirm=True)
            page.fill("#takeoff-alt", str(altitude_m))
            flows.click_and_wait_result(page, "#btn-takeoff")
            wait_for_blocking(
                "the page's take-off", lambda: _alt_rel_m(self.state()) > altitude_m - 0.8, 120.0
            )
            page.select_option("#sp-type", "position")
            page.click("#sp-from-here")
            flows.click_and_wait_result(page, "#btn-offboard-start")
            flows.click_and_wait_result(page, "#btn-rtl")
            wait_for_blocking("landed after the page's return",
                              lambda: not self.state()["armed"], 300.0, every_s=1.0)  # fmt: skip
            page.click("#release")
            page.wait_for_selector("#take-control:not(.hidden)", timeout=10_000)
        finally:
            page.close()
        self.after_a_flight()

    def after_a_flight(self) -> None:
        """Landed, disarmed, and nobody holding control."""
        state = self.state()
        assert state["armed"] is False, state
        assert state["landed_state"] == "ON_GROUND", state
        control = wait_for_blocking(
            "control free", lambda: (c := self.control())["holder"] is None and c, 5.0
        )
        assert control["last_end"] is not None, control
        self.flows += 1

    # -- internals ---------------------------------------------------------------------

    def _start_example(self, name: str) -> subprocess.Popen[str]:
        hidden = modules_not_installed_by_make_run()
        assert {"pytest", "hypothesis"} <= hidden
        assert "httpx" not in hidden
        command = [sys.executable, "-c", _RUNNER, str(ROOT / "examples" / name)]
        command += [json.dumps(sorted(hidden)), self.url, "--vehicle", str(self.vehicle)]
        return subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            cwd=self.workdir, env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )  # fmt: skip

    def _server_side(self) -> str:
        """What the server saw of a failed flow: its stream's figures and its log's tail."""
        try:
            stream = json.dumps(self.state().get("stream"))
        except httpx.HTTPError as exc:
            stream = f"(no state: {exc})"
        log = self.server_log.read_text()[-4000:] if self.server_log is not None else ""
        return f"\n--- the stream now: {stream}\n--- the server's log:\n{log}"

    def _log(self, name: str, output: str) -> None:
        (self.workdir / f"{self.flows:02d}-{name}.log").write_text(output)


def full_chain(chain: Chain, context: Any) -> None:
    """Every documented flow in turn: the README session three times, the two examples, a
    page flight, the README session again; then scripts killed half-way (Ctrl-C, SIGKILL)
    and the next ones still flying, the docs/api.md session last. The first README session
    starts where a flight that ended 10.5 m from the estimator's origin left the vehicle."""
    chain.flight_ending_away()
    for _ in range(3):
        chain.curl_session(README)
    chain.example("fly_square.py")
    chain.example("fly_square_async.py")
    chain.page_flight(context)
    chain.curl_session(README)
    chain.example_killed_half_way("fly_square.py", signal.SIGINT)
    chain.example_killed_half_way("fly_square_async.py", signal.SIGKILL)
    chain.example("fly_square.py")
    chain.curl_session(API_DOC)
    assert chain.flows == 12


def _accepted(answer: httpx.Response) -> None:
    assert answer.status_code == 200, answer.text
    assert answer.json()["result"] == "ACCEPTED", answer.text


def _armable(state: dict[str, Any]) -> bool:
    checks = state.get("arming_checks") or {}
    return checks.get("verdict") in ("ready", "arm_switches_mode")


def _alt_rel_m(state: dict[str, Any]) -> float:
    where = state.get("global") or {}
    return float(where.get("alt_rel_m") or 0.0)
