"""What the dashboard page costs the machine it runs on: CPU time of Chromium's whole process
tree (browser, renderer, GPU and utility processes; CPU time, not wall time) and the page's
JS heap, in the states a pilot leaves a page in: landed, hovering in OFFBOARD, flying a
square in OFFBOARD, four vehicles, each with and without the 3D view, and the page in a
background tab. The server and its simulated vehicles are measured apart (their own CPU
over the same window), so what the page costs is not mixed with what it watches.

Headless Chromium with software rendering (as on a laptop without a usable GPU), 1280x800.

Run: .venv/bin/python -m bench.page_cost [--seconds 20] [--only landed,hovering]
     .venv/bin/python -m bench.page_cost --heap-minutes 30    # JS heap growth over 30 min,
                                                              # added to the last scenarios
     .venv/bin/python -m bench.page_cost --before earlier.json  # a change's figures beside
     .venv/bin/python -m bench.page_cost --before /tmp/base     # the same, measured now
The last form measures another tree's server and page (e.g. `git archive main | tar -x -C
/tmp/base`) with this bench, each of its scenarios just before the same one here, so both
see the same machine.
Writes bench/results/page_cost.json.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx

from bench._markdown import table
from bench._report import Section
from bench._results import RESULTS_DIR, machine_info, write_results
from bench._serve import cpu_seconds
from tests.browser.flows import open_dashboard, settle_vehicle
from tests.browser.harness import CHROMIUM, CHROMIUM_ARGS, Serve, altitude_m, vehicle_state
from tests.waiting import wait_for_blocking as wait_for

ALTITUDE_M = 5.0
# Headless Chromium keeps every page "visible" (another tab in front, a minimised window: both
# seen), so the background tab is told it is hidden the way a browser tells it: the property
# and the event. The page's own reaction is measured; a real browser also throttles timers.
HIDE_PAGE = """
() => {
  Object.defineProperty(document, "visibilityState", { configurable: true, get: () => "hidden" });
  Object.defineProperty(document, "hidden", { configurable: true, get: () => true });
  document.dispatchEvent(new Event("visibilitychange"));
}
"""
SQUARE_SIDE_M = 10.0


def descendants(root: int) -> list[int]:
    """Every live process below ``root`` (from /proc's parent links)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(stat[1]), []).append(int(entry.name))
    found: list[int] = []
    todo = [root]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def _exe(pid: int) -> str:
    try:
        return os.readlink(f"/proc/{pid}/exe")
    except OSError:
        return ""


def tree_cpu_s(select: Callable[[str], bool]) -> dict[int, float]:
    """CPU seconds so far of each process below this one whose executable ``select`` takes."""
    cpu: dict[int, float] = {}
    for pid in descendants(os.getpid()):
        if select(_exe(pid)):
            try:
                cpu[pid] = cpu_seconds(pid)
            except OSError:
                continue  # gone between the listing and the read
    return cpu


def _is_chromium(exe: str) -> bool:
    return "chrom" in Path(exe).name


def _is_python(exe: str) -> bool:
    return Path(exe).name.startswith("python")


def cpu_share(before: dict[int, float], after: dict[int, float], seconds: float) -> float:
    """Percent of one core used over the window by the processes seen at its end (a process
    that started inside the window counts from zero)."""
    used = sum(after[pid] - before.get(pid, 0.0) for pid in after)
    return 100.0 * used / seconds


def js_heap_mb(page: Any) -> float:
    session = page.context.new_cdp_session(page)
    try:
        usage = session.send("Runtime.getHeapUsage")
    finally:
        session.detach()
    return round(float(usage["usedSize"]) / 1e6, 2)


class Pilot:
    """Flies vehicle 1 over REST with a lease, as a script would beside the page."""

    def __init__(self, api: httpx.Client) -> None:
        self.api = api
        taken = api.post("/vehicles/1/control", json={"takeover": True, "force": True,
                                                      "ttl_s": 600})
        taken.raise_for_status()
        self.headers = {"X-Lease-Id": taken.json()["lease_id"]}

    def call(self, method: str, path: str, body: dict[str, Any] | None = None) -> None:
        answer = self.api.request(method, f"/vehicles/1/{path}", json=body or {},
                                  headers=self.headers)
        if answer.status_code != 200:
            raise RuntimeError(f"{method} {path}: {answer.status_code} {answer.text}")

    def hover_in_offboard(self) -> dict[str, float]:
        """OFFBOARD holding where the vehicle is (settled in a hover before the lease)."""
        here = vehicle_state(self.api)["position_ned"]
        self.call("POST", "offboard/start", {"setpoint": {
            "type": "position_ned", "north_m": here["north_m"], "east_m": here["east_m"],
            "down_m": here["down_m"]}})
        wait_for("OFFBOARD", lambda: vehicle_state(self.api)["mode"] == "OFFBOARD", 15.0)
        return {"north_m": here["north_m"], "east_m": here["east_m"], "down_m": here["down_m"]}

    def release(self) -> None:
        self.api.delete("/vehicles/1/control", headers=self.headers)


def fly_square(pilot: Pilot, start: dict[str, float], seconds: float) -> None:
    """Position setpoints around a square until ``seconds`` have passed."""
    corners = [(SQUARE_SIDE_M, 0.0), (SQUARE_SIDE_M, SQUARE_SIDE_M), (0.0, SQUARE_SIDE_M),
               (0.0, 0.0)]
    deadline = time.monotonic() + seconds
    k = 0
    while time.monotonic() < deadline:
        north, east = corners[k % len(corners)]
        pilot.call("PUT", "setpoint", {"type": "position_ned", "north_m": start["north_m"] + north,
                                       "east_m": start["east_m"] + east,
                                       "down_m": start["down_m"]})
        pilot.call("PUT", "control")  # renew
        k += 1
        time.sleep(min(4.0, max(0.0, deadline - time.monotonic())))


@contextmanager
def browser_page(url: str, scene: bool) -> Iterator[Any]:
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS,
                                             headless=True)
        context = browser.new_context(viewport={"width": 1280, "height": 800}, bypass_csp=True)
        try:
            yield open_dashboard(context, url, scene=scene)
        finally:
            browser.close()


def measure_window(page: Any, seconds: float, during: Callable[[], None] | None) -> dict[str, Any]:
    chromium0, server0 = tree_cpu_s(_is_chromium), tree_cpu_s(_is_python)
    t0 = time.monotonic()
    if during is None:
        time.sleep(seconds)  # not a wait: the measuring window
    else:
        during()
    elapsed = time.monotonic() - t0
    chromium1, server1 = tree_cpu_s(_is_chromium), tree_cpu_s(_is_python)
    return {
        "window_s": round(elapsed, 1),
        "page_cpu_pct": round(cpu_share(chromium0, chromium1, elapsed), 1),
        "server_and_sim_cpu_pct": round(cpu_share(server0, server1, elapsed), 1),
        "js_heap_mb": js_heap_mb(page),
        "visibility": page.evaluate("document.visibilityState"),
    }


def start_server(serve: Serve, tree: Path | None) -> None:
    """``serve`` started from this tree's server and page, or from those of ``tree``."""
    if tree is None:
        serve.start()
        return
    before = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = str(tree.resolve())  # the server's process imports from it
    try:
        serve.start()
    finally:
        if before is None:
            del os.environ["PYTHONPATH"]
        else:
            os.environ["PYTHONPATH"] = before


def ready_to_fly(api: httpx.Client) -> bool:
    state = vehicle_state(api)
    return state["home"] is not None and bool(state["ready_to_arm"])


# After viser's canvas shows, software WebGL goes on starting the client in the GPU process
# (its shaders, the environment map's prefiltering) for 10-20 s on a shared 2-core machine,
# at 25-30 % of a core: once per page, not what a page costs while it is open, so not counted.
SCENE_START_S = 20.0
# A 1-pixel read of the scene's canvas: returns once the GPU process has run every command
# queued before it.
GL_ROUND_TRIP = """
(canvas) => {
  const gl = canvas.getContext("webgl2") || canvas.getContext("webgl");
  if (!gl) return false;
  gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
  return true;
}
"""


def scene_started(page: Any) -> None:
    """Waits for viser's canvas, its start-up in the GPU process, and anything queued."""
    canvas = page.frame_locator("#scene").locator("canvas").first
    canvas.wait_for(timeout=60_000)
    time.sleep(SCENE_START_S)  # not a wait for a condition: the start-up's CPU is not counted
    canvas.evaluate(GL_ROUND_TRIP)


def scenario(name: str, seconds: float, tree: Path | None = None) -> dict[str, Any]:
    """One scenario: its own server and browser, settled, then measured (the server and
    page of ``tree`` if given)."""
    vehicles = 4 if name.startswith("four_vehicles") else 1
    scene = not name.endswith("_no3d")
    serve = Serve(extra_args=["--sim-count", str(vehicles)] if vehicles > 1 else [])
    start_server(serve, tree)
    load_before = os.getloadavg()
    try:
        with serve.client() as api:
            wait_for("the vehicle", lambda: api.get("/vehicles").json(), 30.0)
            # a home position and the arming checks passed (the estimator's own start)
            wait_for("ready to fly", lambda: ready_to_fly(api), 60.0)
            pilot: Pilot | None = None
            during: Callable[[], None] | None = None
            if name.startswith(("hovering", "square", "background")):
                settle_vehicle(api, flying=True, altitude=ALTITUDE_M)
                pilot = Pilot(api)
                start = pilot.hover_in_offboard()
                if name.startswith("square"):
                    def during() -> None:
                        assert pilot is not None
                        fly_square(pilot, start, seconds)
            with browser_page(serve.url, scene) as page:
                if name.startswith("background"):
                    page.evaluate(HIDE_PAGE)
                if scene:  # software WebGL takes seconds to start viser's client: not counted
                    scene_started(page)
                time.sleep(3.0)  # the page's start-up (scripts, first states, scene) settles
                if pilot is not None:
                    wait_for("still hovering",
                             lambda: altitude_m(vehicle_state(api)) > ALTITUDE_M - 1.0, 10.0)
                result = measure_window(page, seconds, during)
            if pilot is not None:
                pilot.release()
    finally:
        serve.stop()
        serve.discard_log()
    return {"scenario": name, "vehicles": vehicles, "scene": scene, **result,
            "machine": machine_info(load_before)}


SCENARIOS = ["landed", "landed_no3d", "hovering", "hovering_no3d", "square", "square_no3d",
             "four_vehicles", "four_vehicles_no3d", "background_no3d"]
# The page's CPU (% of one core) it should stay under, by scenario.
TARGET_PCT = {"landed": 6.0, "hovering": 16.0, "landed_no3d": 3.0, "hovering_no3d": 8.0,
              "background_no3d": 1.0}


def heap_growth(minutes: float) -> dict[str, Any]:
    """The JS heap of a page watching a hovering vehicle, sampled each minute."""
    serve = Serve()
    serve.start()
    samples: list[tuple[float, float]] = []
    try:
        with serve.client() as api:
            wait_for("ready to fly", lambda: ready_to_fly(api), 60.0)
            settle_vehicle(api, flying=True, altitude=ALTITUDE_M)
            pilot = Pilot(api)
            pilot.hover_in_offboard()
            with browser_page(serve.url, scene=True) as page:
                t0 = time.monotonic()
                while (elapsed := time.monotonic() - t0) < minutes * 60.0:
                    samples.append((round(elapsed / 60.0, 2), js_heap_mb(page)))
                    pilot.call("PUT", "control")
                    time.sleep(min(60.0, minutes * 60.0 - elapsed))
                samples.append((round((time.monotonic() - t0) / 60.0, 2), js_heap_mb(page)))
            pilot.release()
    finally:
        serve.stop()
        serve.discard_log()
    at5 = next((mb for minute, mb in samples if minute >= 5.0), None)
    return {"minutes": minutes, "measured_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "samples_min_mb": samples,
            "growth_after_5_min": round(samples[-1][1] / at5, 3) if at5 else None}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="each measuring window")
    parser.add_argument("--only", default="", help=f"comma-separated of {','.join(SCENARIOS)}")
    parser.add_argument("--quick", action="store_true", help="landed and hovering, 8 s each")
    parser.add_argument("--heap-minutes", type=float, default=0.0,
                        help="also sample the JS heap of a page over this many minutes")
    parser.add_argument("--before", type=Path, default=None,
                        help="an earlier page_cost.json (another version of the page, measured "
                             "just before): its figures are kept beside these as 'before'; or "
                             "another tree (a directory), whose server and page are measured "
                             "now, each scenario just before this tree's")
    args = parser.parse_args()
    if not CHROMIUM.exists():
        print("no /usr/bin/chromium: run `make chromium` as root", file=sys.stderr)
        return 1
    names = [n for n in args.only.split(",") if n] or (
        ["landed_no3d", "hovering_no3d"] if args.quick else SCENARIOS)
    # the heap alone (`--heap-minutes N` without --only or --quick): added to the scenarios
    # measured last, in the same file
    heap_only = args.heap_minutes > 0 and not args.only and not args.quick
    if heap_only:
        names = []
    seconds = 8.0 if args.quick else args.seconds
    tree = args.before if args.before is not None and args.before.is_dir() else None
    rows: list[dict[str, Any]] = []
    before_rows: list[dict[str, Any]] = []
    for name in names:
        for kept, root, label in ([(before_rows, tree, "before")] if tree else []) + [
                (rows, None, "")]:
            row = scenario(name, seconds, root)
            kept.append(row)
            print(f"{label:>6} {name:>20}: page {row['page_cpu_pct']:5.1f} % of a core, "
                  f"server+sim {row['server_and_sim_cpu_pct']:5.1f} %, JS heap "
                  f"{row['js_heap_mb']} MB ({row['visibility']}, {row['window_s']} s, load "
                  f"{row['machine']['load_average_before'][0]:.2f})", flush=True)
    result: dict[str, Any] = {"scenarios": rows, "machine": machine_info()}
    earlier = RESULTS_DIR / "page_cost.json"
    if heap_only and earlier.exists():
        result = {key: value for key, value in json.loads(earlier.read_text()).items()
                  if key != "written_at"}
    elif args.heap_minutes <= 0 and earlier.exists():
        # the last heap run (30 min) is kept beside the scenarios, with when it was measured
        kept = json.loads(earlier.read_text())
        if kept.get("heap"):
            result["heap"] = {"measured_at": kept["written_at"], **kept["heap"]}
    if tree is not None:
        result["before"] = before_rows
        result["before_tree"] = str(tree)
    elif args.before is not None:
        result["before"] = json.loads(args.before.read_text())["scenarios"]
    if args.heap_minutes > 0:
        result["heap"] = heap_growth(args.heap_minutes)
        print(f"JS heap over {args.heap_minutes} min: {result['heap']['samples_min_mb']}; "
              f"last / at 5 min = {result['heap']['growth_after_5_min']}")
    write_results("page_cost", result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


def _load(row: dict[str, Any]) -> str:
    return f"{row['machine']['load_average_before'][0]:.1f}"


def report(result: dict[str, Any]) -> Section | None:
    """The page's CPU and heap by scenario, against its targets (and the version before)."""
    before = {row["scenario"]: row for row in result.get("before", [])}
    headers = ["scenario", "page CPU % of one core", "load", "target", "server + sim %",
               "JS heap MB", "page says"]
    if before:
        headers[1:1] = ["before: page CPU %", "load"]
    rows = []
    for row in result["scenarios"]:
        name = row["scenario"]
        cells: list[Any] = [f"`{name}`", row["page_cpu_pct"], _load(row),
                            f"≤ {TARGET_PCT[name]:g}" if name in TARGET_PCT else "",
                            row["server_and_sim_cpu_pct"], row["js_heap_mb"], row["visibility"]]
        if before:
            old = before.get(name)
            cells[1:1] = [old["page_cpu_pct"], _load(old)] if old else ["", ""]
        rows.append(cells)
    window = result["scenarios"][0]["window_s"] if result["scenarios"] else 0
    measured_now = "before_tree" in result
    text = (
        "CPU time of Chromium's whole process tree (headless, software rendering, 1280×800) "
        f"over {window:.0f} s per scenario, each on its own server with one simulated quad "
        "(`_no3d`: the 3D view off); 'load' is the machine's 1-minute load average as the "
        "scenario started (2 CPUs, shared). `background_no3d` is the page told it is hidden "
        "(the `visibilityState` property and the `visibilitychange` event, as a browser tells "
        "a background tab: headless Chromium keeps every page visible, and a real browser also "
        "throttles a background tab's timers). "
        + (("'before' is the previous version of the server and page (`--before "
            f"{result['before_tree']}`), each scenario measured just before the same one of "
            "this version, in the same run. ") if measured_now else
           ("'before' is the previous version of the page (and of the scene), measured just "
            "before on the same machine. ") if before else "")
        + f"With the 3D view on, the window starts {SCENE_START_S:.0f} s after viser's canvas "
        "shows (software WebGL's start-up in the GPU process, 25–30 % of a core for 10–20 s "
        "once per page, is not counted). "
        "Viser's client draws for 250 ms after every change it is sent "
        "and once a second when idle; the page it is served in paces it (server/scene/pace.js): "
        "every frame while the pilot drives the view, at most 30 a second for 400 ms after a "
        "scene message, else a frame asked for waits up to 10 s. The page asks its telemetry "
        "on change (`on_change=true`, docs/api.md): a landed vehicle's page gets 2–3 states a "
        "second instead of 10. While a vehicle streams, the stream's running counters (frames "
        "sent, time since the last) and the plots are drawn on one half-second beat "
        "(web/draw.js); the numbers of each state at once.\n\n"
        + table(headers, rows))
    names = ",".join(row["scenario"] for row in result["scenarios"])
    command = f".venv/bin/python -m bench.page_cost --only {names} --seconds {window:.0f}"
    if measured_now:
        text += ("\n\nMeasured with `git archive main | tar -x -C "
                 f"{result['before_tree']}` (the version before) and `{command} --before "
                 f"{result['before_tree']}`.")
    heap = result.get("heap")
    if heap:
        when = f" (measured {heap['measured_at']})" if heap.get("measured_at") else ""
        text += (f"\n\nJS heap over {heap['minutes']:g} min{when}: last / at 5 min = "
                 f"{heap['growth_after_5_min']} (samples, minute and MB: "
                 f"{heap['samples_min_mb']}).")
    return Section("What the page costs the machine it runs on", 76, text)
