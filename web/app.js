// SkyHelm dashboard: wires the public API to the page. Nothing here talks MAVLink; every
// answer shown is the one the API returned. The page polls nothing: state, events, the
// vehicle list and clicks in the 3D scene all come on the telemetry socket.

import { TelemetrySocket, request, token } from "./api.js";
import {
  confirmThen, continueHold, currentBody, inControl, offsetLatLon, panel, releaseControl,
  renderHolder, reposition, runCommand, showResult, showSetpointType, takeControl, updateControls,
} from "./control.js";
import { SETPOINT_TYPES } from "./offboard.js";
import { page, plots } from "./page.js";
import { render } from "./render.js";
import { $, banner, log, nowS, num, setText } from "./ui.js";

const FALLBACK_MODES = [
  "MANUAL", "ALTCTL", "POSCTL", "POSCTL_ORBIT", "ACRO", "STABILIZED", "OFFBOARD", "HOLD",
  "TAKEOFF", "LAND", "RTL", "MISSION", "FOLLOW_TARGET", "PRECLAND", "VTOL_TAKEOFF",
  "TERMINATION", "RATTITUDE", "READY",
];
const OFFBOARD_PARAMS = [
  "COM_OF_LOSS_T", "COM_OBL_RC_ACT", "COM_RC_IN_MODE", "MIS_TAKEOFF_ALT", "RTL_RETURN_ALT",
  "RTL_DESCEND_ALT", "RTL_LAND_DELAY",
];
// ---- telemetry ----------------------------------------------------------------------------

function onTelemetry(message) {
  if (message.type === "statustext") {
    log(message.severity || "INFO", message.text || "");
  } else if (message.type === "event") {
    onEvent(message);
  } else if (message.type === "state") {
    if (message.vehicle !== page.vehicleId) return; // a socket for every vehicle, before one is chosen
    render(message);
    renderHolder(message.lease?.holder);
    continueHold(message);
  } else if (message.type === "vehicles") {
    showVehicles(message.vehicles);
  } else if (message.type === "scene_click") {
    onSceneClick(message);
  }
}

function onEvent(message) {
  const data = message.data || {};
  if (message.kind === "mode") {
    log("INFO", `mode ${data.from ?? ""} → ${data.to ?? data.mode ?? JSON.stringify(data)}`);
  } else if (message.kind === "armed") {
    log("INFO", data.armed ? "armed" : "disarmed");
  } else if (message.kind === "command") {
    return; // this page logs its own answers; what others' commands did shows as mode/armed events
  } else {
    const text = data.text || data.reason || Object.entries(data)
      .filter(([, v]) => v !== null && v !== undefined)
      .map(([k, v]) => `${k} ${typeof v === "object" ? JSON.stringify(v) : v}`).join(", ");
    const severity = message.kind === "deadman" ? "WARNING" : message.kind === "lease" ? "NOTICE" : "INFO";
    log(severity, `${message.kind}: ${text}`);
  }
}

function onTelemetryStatus(status) {
  page.connected = status.state === "connected";
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
    banner("Connection to the server lost — reconnecting…");
  }
  updateControls();
}

function reloadAfterReconnect() {
  // the vehicle list comes by itself on the new socket
  showScene($("scene-enable").checked);
  loadParams();
  if (page.wantControl && !page.control) {
    log("NOTICE", "taking control again");
    takeControl(false);
  }
}

// ---- vehicles -----------------------------------------------------------------------------

async function loadServerMode() {
  try {
    page.readOnly = Boolean((await request("GET", "/health")).read_only);
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
    showVehicles(await request("GET", "/vehicles"));
  } catch (err) {
    log("ERROR", `vehicle list: ${err.message}`);
  }
}

function showVehicles(vehicles) {
  page.vehicles = vehicles;
  const select = $("vehicle-select");
  const previous = page.vehicleId;
  select.replaceChildren(...vehicles.map((v) => {
    const option = document.createElement("option");
    option.value = v.id;
    option.textContent = `${v.id} · ${v.type}${v.connected ? "" : " (lost)"}`;
    return option;
  }));
  const keep = vehicles.find((v) => v.id === previous);
  const chosen = keep || vehicles[0];
  if (!chosen) {
    // no vehicle yet: a socket for all of them, to hear of the first one
    if (!page.telemetry) watchTelemetry(null);
    return;
  }
  select.value = chosen.id;
  page.vehicleType = chosen.type;
  if (!keep) selectVehicle(chosen.id);
}

function watchTelemetry(vehicleId) {
  page.telemetry?.close();
  page.telemetry = new TelemetrySocket(vehicleId, { onMessage: onTelemetry, onStatus: onTelemetryStatus });
}

function selectVehicle(id) {
  releaseControl();
  page.vehicleId = Number(id);
  page.vehicleType = page.vehicles.find((v) => v.id === page.vehicleId)?.type || "";
  page.state = null;
  plots.alt.clear();
  plots.speed.clear();
  watchTelemetry(page.vehicleId);
  loadParams();
}

// ---- 3D scene -----------------------------------------------------------------------------

function onSceneClick(click) {
  if (!Number.isFinite(click.lat_deg)) return; // before the scene knows where it is
  $("repo-lat").value = click.lat_deg.toFixed(7);
  $("repo-lon").value = click.lon_deg.toFixed(7);
  const overlay = $("scene-click");
  overlay.textContent = `clicked N ${num(click.north_m)} m, E ${num(click.east_m)} m → ${num(click.lat_deg, 6)}, ${num(click.lon_deg, 6)}`;
  overlay.classList.remove("hidden");
  if ($("repo-on-click").checked && inControl()) reposition(click.lat_deg, click.lon_deg, "Reposition (scene click)");
}

function sceneUrl() {
  return `/scene/?token=${encodeURIComponent(token)}&darkMode`;
}

// The 3D scene renders continuously; switching it off frees the CPU on weak machines.
function showScene(on) {
  $("scene").src = on ? sceneUrl() : "about:blank";
  $("scene").classList.toggle("hidden", !on);
  $("scene-off").classList.toggle("hidden", on);
}

// ---- parameters ---------------------------------------------------------------------------

async function loadParams() {
  const table = $("params");
  if (page.vehicleId === null) return;
  let values = {};
  try {
    values = (await request("GET", `/vehicles/${page.vehicleId}/params?names=${OFFBOARD_PARAMS.join(",")}`)).params || {};
  } catch (err) {
    log("WARNING", `parameters: ${err.message}`);
  }
  table.replaceChildren(...OFFBOARD_PARAMS.map((name) => {
    const row = document.createElement("tr");
    const value = values[name];
    row.innerHTML = `<td>${name}</td><td class="val" id="param-${name}">${value ?? "–"}</td>`
      + `<td><input class="ctl" id="param-input-${name}" type="number" step="any"></td>`
      + `<td><button class="ctl mini" id="param-set-${name}">Set</button></td>`;
    row.querySelector("input").value = value ?? "";
    row.querySelector("button").addEventListener("click", () => setParam(name));
    return row;
  }));
  updateControls();
}

async function setParam(name) {
  const raw = $(`param-input-${name}`).value;
  const value = Number(raw);
  if (raw === "" || !Number.isFinite(value)) return;
  try {
    const answer = await request("PUT", `/vehicles/${page.vehicleId}/params/${name}`, { value },
      { "X-Lease-Id": page.control?.leaseId || "" });
    $(`param-${name}`).textContent = answer.value;
    showResult(`${name}`, { ok: true, body: { result: `= ${answer.value}` } });
  } catch (err) {
    showResult(`${name}`, { ok: false, status: err.status, body: err.body });
  }
}

// ---- modes --------------------------------------------------------------------------------

async function loadModes() {
  let modes = FALLBACK_MODES;
  try {
    const schema = await (await fetch("/openapi.json")).json();
    const fromSchema = schema.components?.schemas?.ModeBody?.properties?.mode?.enum;
    if (Array.isArray(fromSchema) && fromSchema.length) modes = fromSchema;
  } catch {
    // the built-in list matches PX4's modes
  }
  $("mode-select").replaceChildren(...modes.map((m) => {
    const option = document.createElement("option");
    option.value = option.textContent = m;
    return option;
  }));
  $("mode-select").value = "HOLD";
}

// ---- wiring -------------------------------------------------------------------------------

function wire() {
  $("vehicle-select").addEventListener("change", (e) => selectVehicle(e.target.value));
  $("take-control").addEventListener("click", () => takeControl(false));
  $("take-over").addEventListener("click", () => takeControl(true));
  $("release").addEventListener("click", releaseControl);
  confirmThen($("btn-arm"), () => runCommand("Arm", "arm", {}, $("btn-arm")));
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
  $("sp-from-here").addEventListener("click", () => showSetpointType(panel.type));
  $("btn-offboard-start").addEventListener("click", (e) => runCommand("Start offboard", "offboard_start", { setpoint: currentBody() }, e.target));
  $("btn-offboard-stop").addEventListener("click", (e) => runCommand("Stop offboard", "offboard_stop", { then_mode: "HOLD" }, e.target));
  $("btn-repo-global").addEventListener("click", (e) => {
    const lat = parseFloat($("repo-lat").value);
    const lon = parseFloat($("repo-lon").value);
    if (!Number.isFinite(lat) || !Number.isFinite(lon)) {
      showResult("Reposition", { ok: false, status: 422, body: { detail: { reason: "enter lat and lon" } } });
      return;
    }
    reposition(lat, lon, "Reposition", e.target);
  });
  $("btn-repo-offset").addEventListener("click", (e) => {
    const g = page.state?.global;
    if (!g) {
      showResult("Reposition", { ok: false, status: 0, body: { detail: { reason: "no global position yet" } } });
      return;
    }
    const north = parseFloat($("repo-north").value) || 0;
    const east = parseFloat($("repo-east").value) || 0;
    const [lat, lon] = offsetLatLon(g.lat_deg, g.lon_deg, north, east);
    reposition(lat, lon, `Reposition ${north} N ${east} E`, e.target);
  });
  $("btn-to-fw").addEventListener("click", (e) => runCommand("Transition to FW", "vtol_transition", { to: "fixed_wing" }, e.target));
  $("btn-to-mc").addEventListener("click", (e) => runCommand("Transition to MC", "vtol_transition", { to: "multicopter" }, e.target));
  $("params-refresh").addEventListener("click", loadParams);
  $("scene-enable").addEventListener("change", (e) => showScene(e.target.checked));
  window.addEventListener("pagehide", () => page.control?.close());
}

function drawLoop() {
  const t = nowS();
  plots.alt.draw(t);
  plots.speed.draw(t);
  setTimeout(() => requestAnimationFrame(drawLoop), 200);
}

async function main() {
  if (!token) {
    banner("Open the URL printed by `skyhelm serve` (it carries ?token=…)");
  }
  if (new URLSearchParams(location.search).get("scene") === "off") $("scene-enable").checked = false;
  wire();
  showSetpointType("position");
  updateControls();
  showScene($("scene-enable").checked);
  await loadServerMode();
  await loadModes();
  await loadVehicles();
  drawLoop();
  log("INFO", "dashboard ready");
}

main();

// The page's state, for the browser console and the browser tests.
window.skyhelm = { page, SETPOINT_TYPES };
