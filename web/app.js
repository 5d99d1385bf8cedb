// SkyHelm dashboard: wires the public API to the page. Nothing here talks MAVLink; every
// answer shown is the one the API returned. The page polls nothing: state, events, the
// vehicle list and clicks in the 3D scene all come on the telemetry socket.

import { Alerts, alertLog } from "./alerts.js";
import { TelemetrySocket, callApi, onTokenRejected, reconnectDelayMs, token } from "./api.js";
import {
  brake, confirmThen, followAgain, goByOffset, goTo, keyboard, runCommand, showResult,
  showSetpointType, startOffboard,
} from "./control.js";
import {
  answerPrompt, clientLabel, clientName, inControl, onControlEvent, releaseControl, renderHolder,
  serverBack, setClientLabel, tabId, takeControl, takeControlClicked, updateControls,
  vehicleHeard,
} from "./handover.js";
import { confirmAction, wireConfirm } from "./confirm.js";
import { Painter, drawTimes, draws, setAttr } from "./draw.js";
import { FleetView } from "./fleet.js";
import { deadmanText } from "./format.js";
import { wireLayout } from "./layout.js";
import { VehicleMap } from "./map.js";
import { modeMenu, modesFor } from "./modes.js";
import { SETPOINT_TYPES } from "./offboard.js";
import { freshness, page, plots } from "./page.js";
import { ParamEditor } from "./params.js";
import { readiness } from "./readiness.js";
import { accept, instruments, render } from "./render.js";
import { watchSceneNotices } from "./scene-notice.js";
import { $, banner, log, num, setText } from "./ui.js";

const params = new ParamEditor($("params-editor"));
const map = new VehicleMap($("map"));
const alerts = new Alerts($("alerts"), $("alerts-mute"));
const IN_AIR = new Set(["IN_AIR", "TAKEOFF", "LANDING"]);

// ---- telemetry ----------------------------------------------------------------------------

function onTelemetry(message) {
  if (message.type === "statustext") {
    log(message.severity || "INFO", message.text || "");
    alerts.fromText(message.severity || "INFO", message.text || "");
  } else if (message.type === "event") {
    onEvent(message);
  } else if (message.type === "state") {
    map.onState(message);
    if (message.vehicle !== page.vehicleId) return; // a socket for every vehicle, before one is chosen
    showState(message);
    vehicleHeard();
  } else if (message.type === "vehicles") {
    showVehicles(message.vehicles);
  } else if (message.type === "scene_click") {
    onSceneClick(message);
  }
}

// A state is kept and its alerts raised as it comes; drawn at once (as often as the socket
// brings states, 10 Hz; never twice within 80 ms, so a burst is drawn within 100 ms of its
// last state), never while the page is hidden (then at once when it shows again).
const stateDraw = new Painter("state", () => drawState(page.state), { minGapMs: 80 });

function showState(message) {
  accept(message);
  alerts.fromState(message);
  stateDraw.request();
}

function drawState(message) {
  if (!message) return;
  render(message);
  readiness.show(message);
  renderHolder(message.lease);
  modeMenu.follow(message.vehicle_type || page.vehicleType, message.mode);
}

function onEvent(message) {
  const data = message.data || {};
  if (message.kind === "mode") {
    log("INFO", `mode ${data.from ?? ""} → ${data.to ?? data.mode ?? JSON.stringify(data)}`);
  } else if (message.kind === "armed") {
    log("INFO", data.armed ? "armed" : "disarmed");
  } else if (message.kind === "command") {
    return; // this page logs its own answers; what others' commands did shows as mode/armed events
  } else if (message.kind === "control") {
    onControlEvent(data);
    log("NOTICE", controlText(data));
  } else if (message.kind === "lease") {
    return; // the same changes as the control events, in the older shape
  } else if (message.kind === "params" && data.name) {
    params.vehicleSaid(data.name, data.value);
    log("INFO", `params: ${data.text}`);
  } else if (message.kind === "deadman") {
    const text = deadmanText(data, { vehicleSilentS: freshness.freshestS(), vehicle: message.vehicle ?? page.vehicleId });
    log("WARNING", text);
    alerts.raise("deadman", text, data.ok === false ? "critical" : "warning", { forMs: 15000 });
  } else {
    const text = data.text || data.reason || Object.entries(data)
      .filter(([, v]) => v !== null && v !== undefined)
      .map(([k, v]) => `${k} ${typeof v === "object" ? JSON.stringify(v) : v}`).join(", ");
    const severity = message.kind === "deadman" ? "WARNING" : "INFO";
    log(severity, `${message.kind}: ${text}`);
  }
}

/** "control taken_over: Chrome tab 7f3a (was pilot · Firefox tab 01ab)", "control released:
 * nobody holds it (was pilot · script)". */
function controlText(data) {
  const who = data.holder || data.by || "nobody holds it";
  const was = data.previous_holder ? ` (was ${data.previous_holder})` : "";
  const by = data.by && data.by !== who ? ` by ${data.by}` : "";
  const reason = data.reason ? ` — ${data.reason}` : "";
  return `control ${(data.action || "").replaceAll("_", " ")}: ${who}${by}${was}${reason}`;
}

function onTelemetryStatus(status) {
  page.connected = status.state === "connected";
  if (page.connected) page.everConnected = true;
  const inS = Math.ceil((status.retryInMs ?? 0) / 1000);
  // one alert says the server is lost (the SERVER box too); before it ever answered, a banner
  if (page.everConnected) alerts.fromServer(page.connected, inS);
  if (page.connected) {
    setText("conn-status", "connected", "ok");
    if (status.reconnected) {
      banner("Reconnected to the server", true);
      log("NOTICE", "reconnected to the server");
      reloadAfterReconnect();
    } else {
      banner("");
    }
  } else {
    setText("conn-status", "reconnecting…", "bad");
    banner(page.everConnected ? "" : `Cannot reach the server — trying again${inS ? ` in ${inS} s` : ""}…`);
  }
  updateControls();
}

function reloadAfterReconnect() {
  serverBack();
  // the vehicle list comes by itself on the new socket
  showScene($("scene-enable").checked);
  loadParams();
  if (page.wantControl && !page.control) {
    log("NOTICE", "taking control again");
    takeControl("take");
  }
}

// ---- vehicles -----------------------------------------------------------------------------

async function loadServerMode() {
  try {
    page.readOnly = Boolean((await callApi("health")).read_only);
  } catch (err) {
    log("ERROR", `server health: ${err.message}`);
    return;
  }
  if (page.readOnly) {
    banner("");
    updateControls();
  }
}

// Once at start; after that the telemetry socket brings the list whenever it changes.
async function loadVehicles() {
  try {
    showVehicles(await callApi("vehicles"));
  } catch (err) {
    log("ERROR", `vehicle list: ${err.message}`);
    // the telemetry socket brings the list when the server answers
    if (!page.telemetry && !page.rejected) watchTelemetry(null);
  }
}

// The token was refused: nothing more will work, so stop asking and say what to do.
function tokenRejected(reason) {
  page.rejected = true;
  page.wantControl = false;
  page.telemetry?.close();
  page.control?.close();
  map.stop();
  page.connected = false;
  $("scene").src = "about:blank";
  setText("conn-status", "token rejected", "bad");
  banner("This link's token was rejected: open the URL printed by `skyhelm serve` (ask for a new link)", false, true);
  log("ERROR", `token rejected: ${reason}`);
  updateControls();
}

function showVehicles(vehicles) {
  page.vehicles = vehicles;
  map.showVehicles(vehicles);
  const select = $("vehicle-select");
  const previous = page.vehicleId;
  const listed = vehicles.map((v) => `${v.id} · ${shortType(v.type)}`);
  const titles = vehicles.map((v) => `vehicle ${v.id}: ${v.type}${v.connected ? "" : " (lost)"}`);
  const key = titles.join("\n");
  if (select.dataset.listed !== key) { // the same list: nothing to redraw
    select.dataset.listed = key;
    select.replaceChildren(...vehicles.map((v, i) => {
      const option = document.createElement("option");
      option.value = v.id;
      option.textContent = listed[i];
      option.title = titles[i];
      return option;
    }));
  }
  if (page.fleetVehicle) { // another edge's vehicle is shown: the local list stays a list
    select.value = "";
    setAttr(select, "title", "");
    return;
  }
  const keep = vehicles.find((v) => v.id === previous);
  const chosen = keep || vehicles[0];
  if (!chosen) {
    // no vehicle yet: a socket for all of them, to hear of the first one
    if (!page.telemetry) watchTelemetry(null);
    return;
  }
  select.value = chosen.id;
  setAttr(select, "title", select.selectedOptions[0]?.title || "");
  page.vehicleType = chosen.type;
  if (!keep) selectVehicle(chosen.id);
}

// The vehicle menu's short names (the whole MAV_TYPE in its tooltip), so "1 · quad" fits the
// top bar's slot at 1024 px.
const SHORT_TYPES = {
  QUADROTOR: "quad", HEXAROTOR: "hexa", OCTOROTOR: "octo", TRICOPTER: "tri", HELICOPTER: "heli",
  FIXED_WING: "plane", GROUND_ROVER: "rover", SURFACE_BOAT: "boat", SUBMARINE: "sub",
};

function shortType(type) {
  const name = String(type || "").toUpperCase();
  if (name.startsWith("VTOL")) return "VTOL";
  return SHORT_TYPES[name] || name.toLowerCase().slice(0, 8);
}

function watchTelemetry(vehicleId) {
  page.telemetry?.close();
  page.telemetry = new TelemetrySocket(vehicleId, { onMessage: onTelemetry, onStatus: onTelemetryStatus });
}

function selectVehicle(id) {
  if (page.rejected) return;
  releaseControl();
  page.fleetVehicle = null;
  page.vehicleId = Number(id);
  page.vehicleType = page.vehicles.find((v) => v.id === page.vehicleId)?.type || "";
  page.state = null;
  map.vehicleChanged();
  plots.clear();
  instruments.reset();
  alerts.clearAll();
  watchTelemetry(page.vehicleId);
  loadParams();
}

// ---- the fleet (a fleet server) ---------------------------------------------------------------

const fleet = new FleetView($("fleet-panel"), map, {
  onSelect: selectFleetVehicle,
  onSelectedState: showState,
  onSelectedEvent: (event) => onEvent(event),
});

/** Another edge's vehicle: shown like a local one, flown through the fleet server. */
function selectFleetVehicle(vehicle) {
  if (page.rejected) return;
  releaseControl();
  page.fleetVehicle = vehicle;
  page.vehicleId = vehicle.key;
  page.vehicleType = vehicle.type;
  page.state = null;
  $("vehicle-select").value = "";
  map.vehicleChanged();
  plots.clear();
  instruments.reset();
  alerts.clearAll();
  // the local socket stays, for every local vehicle on the map and the server's status
  if (!page.telemetry || page.telemetry.vehicleId !== null) watchTelemetry(null);
  log("INFO", `fleet vehicle ${vehicle.key} selected`);
  loadParams();
}

document.addEventListener("skyhelm-fleet-select", (e) => fleet.select(e.detail));

// ---- 3D scene -----------------------------------------------------------------------------

function onSceneClick(click) {
  if (!Number.isFinite(click.lat_deg)) return; // before the scene knows where it is
  $("repo-lat").value = click.lat_deg.toFixed(7);
  $("repo-lon").value = click.lon_deg.toFixed(7);
  const overlay = $("scene-click");
  overlay.textContent = `clicked N ${num(click.north_m)} m, E ${num(click.east_m)} m → ${num(click.lat_deg, 6)}, ${num(click.lon_deg, 6)}`;
  overlay.classList.remove("hidden");
  if ($("repo-on-click").checked && inControl()) goTo(click.lat_deg, click.lon_deg, "Go to the clicked point");
}

function sceneUrl() {
  return "/scene/?darkMode"; // the session cookie carries the token (api.js)
}

// The 3D scene costs CPU without a GPU; switching it off frees it on weak machines. A server
// without the scene (--no-scene, GET /config says so) is never asked for it.
function showScene(on) {
  if (page.rejected || page.sceneServed === undefined) return; // not known yet: nothing asked
  const shown = on && page.sceneServed;
  $("scene").src = shown ? sceneUrl() : "about:blank";
  $("scene").classList.toggle("hidden", !shown);
  $("scene-off").classList.toggle("hidden", shown);
  if (!page.sceneServed) $("scene-off").textContent = "no 3D scene on this server";
}

// ---- parameters ---------------------------------------------------------------------------

function loadParams() {
  params.load();
}

// ---- wiring -------------------------------------------------------------------------------

function wire() {
  $("vehicle-select").addEventListener("change", (e) => {
    e.target.title = e.target.selectedOptions[0]?.title || "";
    selectVehicle(e.target.value);
  });
  $("take-control").addEventListener("click", takeControlClicked);
  confirmThen($("force-control"), () => takeControl("force"));
  $("release").addEventListener("click", releaseControl);
  $("grant-control").addEventListener("click", () => answerPrompt(true));
  $("deny-control").addEventListener("click", () => answerPrompt(false));
  $("client-label").value = clientLabel();
  sizeLabelInput();
  $("client-label").addEventListener("input", sizeLabelInput);
  setText("tab-id", `tab ${tabId()}`);
  $("client-label").title = `this tab is "${clientName()}" to the others`;
  $("client-label").addEventListener("change", (e) => setClientLabel(e.target.value));
  // in the air a slip would be costly: a dialog that says so, instead of the second click
  $("btn-arm").addEventListener("click", (e) => {
    const landed = page.state?.landed_state;
    if (!IN_AIR.has(landed)) return;
    e.stopImmediatePropagation();
    confirmAction({
      title: "Arm in the air?",
      text: `The vehicle reports ${landed.replace("_", " ").toLowerCase()}. Arm it anyway?`,
      confirm: "Arm in the air",
    }).then((ok) => { if (ok) runCommand("Arm", "arm", {}, $("btn-arm")); });
  });
  confirmThen($("btn-arm"), () => runCommand("Arm", "arm", {}, $("btn-arm")));
  $("btn-kill").addEventListener("click", async (e) => {
    const flying = IN_AIR.has(page.state?.landed_state);
    const ok = await confirmAction({
      title: "Kill the motors?",
      text: `The motors stop at once${flying ? " and the vehicle falls: it is in the air" : ""}. This is PX4's forced disarm.`,
      confirm: "Kill",
    });
    if (ok) runCommand("Kill", "disarm", { force: true }, e.target);
  });
  confirmThen($("btn-disarm"), () => runCommand("Disarm", "disarm", {}, $("btn-disarm")));
  $("btn-takeoff").addEventListener("click", (e) => {
    const alt = parseFloat($("takeoff-alt").value);
    runCommand("Takeoff", "takeoff", Number.isFinite(alt) ? { altitude_m: alt } : {}, e.target);
  });
  $("btn-land").addEventListener("click", (e) => runCommand("Land", "land", {}, e.target));
  $("btn-rtl").addEventListener("click", (e) => runCommand("Return", "rtl", {}, e.target));
  $("btn-hold").addEventListener("click", (e) => runCommand("Hold", "hold", {}, e.target));
  $("btn-set-mode").addEventListener("click", (e) => {
    const mode = $("mode-select").value;
    runCommand(`Mode ${mode}`, "mode", { mode }, e.target);
  });
  $("sp-type").addEventListener("change", (e) => showSetpointType(e.target.value));
  $("sp-from-here").addEventListener("click", followAgain);
  $("btn-offboard-start").addEventListener("click", (e) => startOffboard(e.target));
  $("btn-brake").addEventListener("click", (e) => brake(e.target));
  $("btn-offboard-stop").addEventListener("click", (e) => runCommand("Stop offboard", "offboard_stop", { then_mode: "HOLD" }, e.target));
  $("btn-repo-global").addEventListener("click", (e) => {
    const lat = parseFloat($("repo-lat").value);
    const lon = parseFloat($("repo-lon").value);
    if (!Number.isFinite(lat) || !Number.isFinite(lon)) {
      showResult("Go to", { ok: false, status: 422, body: { detail: { reason: "enter lat and lon" } } });
      return;
    }
    goTo(lat, lon, "Go to lat/lon", e.target);
  });
  $("btn-repo-offset").addEventListener("click", (e) => goByOffset(e.target));
  $("btn-to-fw").addEventListener("click", (e) => runCommand("Transition to FW", "vtol_transition", { to: "fixed_wing" }, e.target));
  $("btn-to-mc").addEventListener("click", (e) => runCommand("Transition to MC", "vtol_transition", { to: "multicopter" }, e.target));
  $("params-refresh").addEventListener("click", loadParams);
  $("scene-enable").addEventListener("change", (e) => showScene(e.target.checked));
  window.addEventListener("pagehide", () => page.control?.close());
}

/** This tab's name box as wide as the name (so "Chrome (headless)" is never cut). */
function sizeLabelInput() {
  const input = $("client-label");
  const cs = getComputedStyle(input);
  sizeLabelInput.context ??= document.createElement("canvas").getContext("2d");
  const context = sizeLabelInput.context;
  context.font = cs.font;
  const edges = ["paddingLeft", "paddingRight", "borderLeftWidth", "borderRightWidth"]
    .reduce((sum, key) => sum + (parseFloat(cs[key]) || 0), 0);
  const text = Math.ceil(context.measureText(input.value || "tab").width);
  input.style.width = `${Math.min(220, Math.max(48, text + edges + 3))}px`;
}

async function main() {
  onTokenRejected(tokenRejected);
  if (!token) {
    banner("Open the URL printed by `skyhelm serve` (it carries ?token=…)");
  }
  if (new URLSearchParams(location.search).get("scene") === "off") $("scene-enable").checked = false;
  wireConfirm();
  document.addEventListener("skyhelm-control-taken", (e) => alerts.controlTaken(e.detail.by));
  document.addEventListener("skyhelm-control-regained", () => alerts.clear("control"));
  wire();
  wireLayout(map);
  watchSceneNotices($("scene"));
  showSetpointType("position");
  updateControls();
  await loadServerMode();
  page.sceneServed = (await map.loadConfig())?.scene !== false;
  showScene($("scene-enable").checked);
  await modeMenu.load();
  await fleet.start();
  await loadVehicles();
  log("INFO", "dashboard ready");
}

main();

// The page's state, for the browser console and the browser tests.
window.skyhelm = {
  page, SETPOINT_TYPES, keyboard, modesFor, reconnectDelayMs, alerts, alertLog, plots, freshness,
  map, fleet, draws, drawTimes,
};
