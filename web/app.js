// SkyHelm dashboard: wires the public API to the page. Nothing here talks MAVLink; every
// answer shown is the one the API returned.

import { ControlSession, TelemetrySocket, describeError, request, token } from "./api.js";
import { StripChart } from "./plots.js";
import { KeyboardPilot, SETPOINT_TYPES, SetpointPanel, setpointBody, valuesFromState } from "./offboard.js";

const $ = (id) => document.getElementById(id);

const FALLBACK_MODES = [
  "MANUAL", "ALTCTL", "POSCTL", "POSCTL_ORBIT", "ACRO", "STABILIZED", "OFFBOARD", "HOLD",
  "TAKEOFF", "LAND", "RTL", "MISSION", "FOLLOW_TARGET", "PRECLAND", "VTOL_TAKEOFF",
  "TERMINATION", "RATTITUDE", "READY",
];
const OFFBOARD_PARAMS = [
  "COM_OF_LOSS_T", "COM_OBL_RC_ACT", "COM_RC_IN_MODE", "MIS_TAKEOFF_ALT", "RTL_RETURN_ALT",
  "RTL_DESCEND_ALT", "RTL_LAND_DELAY",
];
const SETPOINT_SEND_INTERVAL_MS = 50;
const CONFIRM_WINDOW_MS = 4000;
const EARTH_RADIUS_M = 6378137;
const LOG_LIMIT = 400;
const RETAKE_DELAY_MS = 1000;

const page = {
  vehicles: [],
  vehicleId: null,
  vehicleType: "",
  telemetry: null,
  control: null,
  wantControl: false,
  connected: false,
  state: null,
  lastClickSeq: null,
  vtol: { state: null, since: 0 },
  readOnly: false, // a replayed recording: nobody may take control
};

const REPLAY_NOTICE = "Replay of a recording — observe only";

const plots = {
  alt: new StripChart($("plot-alt"), { unit: "m", minSpan: 2 }),
  speed: new StripChart($("plot-speed"), { unit: "m/s", minSpan: 1 }),
};

// ---- small helpers ------------------------------------------------------------------------

const num = (x, digits = 1) => (Number.isFinite(x) ? x.toFixed(digits) : "–");
const nowS = () => performance.now() / 1000;

function setText(id, text, cls) {
  const el = $(id);
  if (el.textContent !== text) el.textContent = text;
  if (cls !== undefined && el.dataset.cls !== cls) {
    if (el.dataset.cls) el.classList.remove(el.dataset.cls);
    if (cls) el.classList.add(cls);
    el.dataset.cls = cls;
  }
}

function log(severity, text, time = new Date()) {
  const box = $("log");
  const line = document.createElement("div");
  line.className = `sev-${severity}`;
  const t = document.createElement("span");
  t.className = "t";
  t.textContent = time.toTimeString().slice(0, 8);
  const sev = document.createElement("span");
  sev.className = "t";
  sev.textContent = severity.padEnd(8);
  line.append(t, sev, document.createTextNode(text));
  const atBottom = box.scrollHeight - box.scrollTop - box.clientHeight < 20;
  box.append(line);
  while (box.childElementCount > LOG_LIMIT) box.firstElementChild.remove();
  if (atBottom) box.scrollTop = box.scrollHeight;
}

function banner(text, ok = false) {
  const el = $("banner");
  // A replay keeps saying so whenever no other message is showing.
  const shown = text || (page.readOnly ? REPLAY_NOTICE : "");
  el.textContent = shown;
  el.classList.toggle("ok", ok);
  el.classList.toggle("hidden", !shown);
  clearTimeout(banner.timer);
  if (ok) banner.timer = setTimeout(() => banner(""), 3000);
}

// ---- command answers ----------------------------------------------------------------------

function showResult(label, answer) {
  const body = answer.body || {};
  let text;
  let cls;
  if (answer.ok) {
    text = `${label}: ${body.result || "OK"}${body.elapsed_ms !== undefined ? ` (${num(body.elapsed_ms, 0)} ms)` : ""}`;
    cls = "ok";
  } else if (body.result) {
    text = `${label}: ${body.result}${body.reason ? ` — ${body.reason}` : ""}`;
    cls = "bad";
  } else {
    text = `${label}: refused — ${describeError(answer.status, body)}`;
    cls = "bad";
  }
  const el = $("result");
  el.textContent = text;
  el.className = `result ${cls}`;
  log(answer.ok ? "OK" : "ERROR", text);
}

async function runCommand(label, name, args, button) {
  if (!page.control) return;
  const el = $("result");
  el.textContent = `${label}: sent, waiting for the vehicle…`;
  el.className = "result pending";
  button?.classList.add("busy");
  try {
    showResult(label, await page.control.command(name, args));
  } finally {
    button?.classList.remove("busy");
  }
}

function confirmThen(button, action) {
  button.addEventListener("click", () => {
    if (button.classList.contains("confirming")) {
      clearTimeout(button.confirmTimer);
      button.classList.remove("confirming");
      button.textContent = button.dataset.label;
      action();
      return;
    }
    button.dataset.label = button.textContent;
    button.textContent = button.dataset.confirm;
    button.classList.add("confirming");
    button.confirmTimer = setTimeout(() => {
      button.classList.remove("confirming");
      button.textContent = button.dataset.label;
    }, CONFIRM_WINDOW_MS);
  });
}

// ---- control lease ------------------------------------------------------------------------

function takeControl(takeover = false) {
  if (page.vehicleId === null) return;
  page.control?.close();
  page.wantControl = true;
  const session = new ControlSession(page.vehicleId, {
    takeover,
    clientName: `dashboard ${navigator.userAgent.includes("Headless") ? "(headless)" : ""}`.trim(),
    onLease: (lease) => {
      log("NOTICE", `control taken (lease ${lease.ttl_s} s)`);
      $("take-over").classList.add("hidden");
      updateControls();
    },
    onClosed: (info) => {
      if (page.control === session) page.control = null;
      if (info.byUs) {
        log("NOTICE", "control released");
      } else if (info.code === 4409) {
        page.wantControl = false;
        const holder = info.refusal?.holder || "another pilot";
        log("WARNING", `control is held by ${holder}`);
        $("take-over").classList.remove("hidden");
      } else if (info.code === 4403) {
        page.wantControl = false;
        log("ERROR", `control refused: ${info.reason || "this token may only observe"}`);
      } else if (info.code === 4408) {
        log("WARNING", `control lease lost (${info.reason || "expired"})`);
      } else if (page.wantControl) {
        log("WARNING", "control connection lost; taking control again when the server answers");
        // A blip of the control socket alone: retry while the telemetry socket is up (a
        // server restart is handled when telemetry reconnects).
        setTimeout(() => {
          if (page.wantControl && !page.control && page.connected) takeControl(false);
        }, RETAKE_DELAY_MS);
      }
      updateControls();
    },
  });
  page.control = session;
}

function releaseControl() {
  page.wantControl = false;
  page.control?.close();
  page.control = null;
  updateControls();
}

function inControl() {
  return Boolean(page.control && page.control.open);
}

function renderHolder(holder) {
  const mine = inControl();
  setText("holder", mine ? `you (${page.control.holder || holder || "this page"})` : holder || "nobody");
}

function updateControls() {
  const pilot = inControl() && page.connected;
  document.body.classList.toggle("observing", !pilot);
  for (const el of document.querySelectorAll(".ctl")) el.disabled = !pilot;
  $("take-control").classList.toggle("hidden", inControl() || page.readOnly);
  $("release").classList.toggle("hidden", !inControl());
  renderHolder(page.state?.lease?.holder);
}

// ---- telemetry ----------------------------------------------------------------------------

function onTelemetry(message) {
  if (message.type === "statustext") {
    log(message.severity || "INFO", message.text || "");
  } else if (message.type === "event") {
    onEvent(message);
  } else if (message.type === "state") {
    render(message);
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

async function reloadAfterReconnect() {
  await loadVehicles();
  showScene($("scene-enable").checked);
  loadParams();
  if (page.wantControl && !page.control) {
    log("NOTICE", "taking control again");
    takeControl(false);
  }
}

function altitudeAboveHome(state) {
  if (state.global && Number.isFinite(state.global.alt_rel_m)) return state.global.alt_rel_m;
  if (state.position_ned) return (state.home?.down_m ?? 0) - state.position_ned.down_m;
  return null;
}

function setpointAltitude(state) {
  const sp = state.setpoint;
  const homeDown = state.home?.down_m ?? 0;
  if (sp && Number.isFinite(sp.down_m)) return homeDown - sp.down_m;
  if (sp && Number.isFinite(sp.z)) return homeDown - sp.z;
  if (state.target_ned && Number.isFinite(state.target_ned.down_m)) return homeDown - state.target_ned.down_m;
  return null;
}

function setpointSpeed(state) {
  const sp = state.setpoint;
  if (!sp) return null;
  if (Number.isFinite(sp.north_m_s) && Number.isFinite(sp.east_m_s)) return Math.hypot(sp.north_m_s, sp.east_m_s);
  if (Number.isFinite(sp.forward_m_s) && Number.isFinite(sp.right_m_s)) return Math.hypot(sp.forward_m_s, sp.right_m_s);
  if (Number.isFinite(sp.vx) && Number.isFinite(sp.vy)) return Math.hypot(sp.vx, sp.vy);
  if (Number.isFinite(sp.north_m)) return 0;
  return null;
}

function render(state) {
  page.state = state;
  if (state.vehicle_type) page.vehicleType = state.vehicle_type;
  const link = state.link || {};
  const age = state.last_heartbeat_age_s;
  const loss = link.frames_in ? (100 * (link.lost_frames || 0)) / (link.frames_in + (link.lost_frames || 0)) : 0;
  setText("link-health", `${state.connected ? "" : "LOST · "}hb ${num(age, 1)} s · loss ${num(loss, 1)}%`);
  $("link-health").style.color = state.connected && age < 2 ? "" : "var(--bad)";

  const failsafe = state.user_mode && state.user_mode !== state.mode && state.armed;
  setText("mode", state.mode || "–");
  $("mode").style.color = failsafe ? "var(--bad)" : state.mode === "OFFBOARD" ? "var(--offboard)" : "";
  setText("user-mode", state.user_mode || "–");
  setText("armed", state.armed ? "ARMED" : "DISARMED", state.armed ? "ok" : "");
  const landedCls = { IN_AIR: "info", TAKEOFF: "warn", LANDING: "warn" }[state.landed_state] || "";
  setText("landed", (state.landed_state || "–").replace("_", " "), landedCls);
  const vtol = state.vtol_state && state.vtol_state !== "UNDEFINED";
  $("vtol-state").classList.toggle("hidden", !vtol);
  if (vtol) setText("vtol-state", state.vtol_state.replaceAll("_", " "), state.vtol_state.startsWith("TRANSITION") ? "warn" : "info");

  renderHolder(state.lease?.holder);

  renderTelemetry(state);
  continueHold(state);
  renderStream(state.stream || {});
  renderVtol(state);
  const t = nowS();
  plots.alt.add(t, altitudeAboveHome(state), setpointAltitude(state));
  plots.speed.add(t, state.ground_speed_m_s, setpointSpeed(state));
}

function renderTelemetry(state) {
  const b = state.battery;
  setText("t-battery", b ? `${num(b.voltage_v, 2)} V · ${num(b.current_a, 1)} A · ${num(b.remaining_pct, 0)}%` : "–");
  if (b && Number.isFinite(b.remaining_pct)) $("t-battery").style.color = b.remaining_pct < 20 ? "var(--bad)" : b.remaining_pct < 40 ? "var(--warn)" : "";
  const g = state.gps;
  setText("t-gps", g ? `${g.fix_type} · ${g.satellites} sats · hdop ${num(g.hdop, 1)}` : "–");
  const p = state.position_ned;
  setText("t-pos", p ? `${num(p.north_m)} / ${num(p.east_m)} / ${num(p.down_m)} m` : "–");
  const v = state.velocity_ned;
  setText("t-vel", v ? `${num(v.north_m_s)} / ${num(v.east_m_s)} / ${num(v.down_m_s)} m/s` : "–");
  const gl = state.global;
  setText("t-alt", gl ? `${num(gl.alt_rel_m)} / ${num(gl.alt_amsl_m)} m` : "–");
  setText("t-latlon", gl ? `${num(gl.lat_deg, 6)}, ${num(gl.lon_deg, 6)}` : "–");
  const a = state.attitude;
  setText("t-att", a ? `${num(a.roll_deg)}° / ${num(a.pitch_deg)}° / ${num(a.yaw_deg, 0)}°` : "–");
  setText("t-speed", `${num(state.ground_speed_m_s)} / ${num(state.air_speed_m_s)} m/s`);
  const h = state.home;
  setText("t-home", h ? `${num(h.north_m)} / ${num(h.east_m)} / ${num(h.down_m)} m` : "–");
  setText("t-rtl", state.rtl_phase || "–");
  const out = state.actuator_outputs || [];
  setText("t-motors", out.length ? out.map((x) => num(x * 100, 0)).join(" ") + " %" : "–");
}

function renderStream(s) {
  setText("stream-active", s.active ? "streaming" : "off");
  $("stream-active").style.color = s.active ? "var(--ok)" : "var(--dim)";
  setText("stream-rate", s.rate_hz ? `${num(s.rate_hz, 1)} Hz` : "–");
  setText("stream-p99", Number.isFinite(s.interval_p99_ms) ? `${num(s.interval_p99_ms, 1)} ms` : "–");
  setText("stream-gap", Number.isFinite(s.max_gap_ms) ? `${num(s.max_gap_ms, 0)} ms` : "–");
  setText("stream-since", Number.isFinite(s.since_last_ms) ? `${num(s.since_last_ms, 0)} ms` : "–");
  setText("stream-sent", `${s.sent ?? "–"}`);
  $("stream-gap").style.color = s.max_gap_ms > 500 ? "var(--bad)" : s.max_gap_ms > 100 ? "var(--warn)" : "";
}

const TRANSITION_GUESS_S = { TRANSITION_TO_FW: 3.5, TRANSITION_TO_MC: 1.5 };

function renderVtol(state) {
  const isVtol = /VTOL/.test(page.vehicleType) || (state.vtol_state && state.vtol_state !== "UNDEFINED");
  $("vtol-panel").classList.toggle("hidden", !isVtol);
  if (!isVtol) return;
  const vs = state.vtol_state;
  if (vs !== page.vtol.state) page.vtol = { state: vs, since: nowS() };
  const elapsed = nowS() - page.vtol.since;
  let pct = 0;
  let text = vs;
  if (vs === "FW") pct = 100;
  else if (vs === "TRANSITION_TO_FW") {
    pct = Math.min(95, (100 * elapsed) / TRANSITION_GUESS_S[vs]);
    text = `→ FW ${num(elapsed, 1)} s · airspeed ${num(state.air_speed_m_s)} m/s`;
  } else if (vs === "TRANSITION_TO_MC") {
    pct = Math.max(5, 100 - (100 * elapsed) / TRANSITION_GUESS_S[vs]);
    text = `→ MC ${num(elapsed, 1)} s`;
  }
  $("vtol-progress-bar").style.width = `${pct}%`;
  setText("vtol-progress", text || "–");
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

async function loadVehicles() {
  try {
    page.vehicles = await request("GET", "/vehicles");
  } catch (err) {
    log("ERROR", `vehicle list: ${err.message}`);
    return;
  }
  const select = $("vehicle-select");
  const previous = page.vehicleId;
  select.replaceChildren(...page.vehicles.map((v) => {
    const option = document.createElement("option");
    option.value = v.id;
    option.textContent = `${v.id} · ${v.type}${v.connected ? "" : " (lost)"}`;
    return option;
  }));
  const keep = page.vehicles.find((v) => v.id === previous);
  const chosen = keep || page.vehicles[0];
  if (!chosen) return;
  select.value = chosen.id;
  page.vehicleType = chosen.type;
  if (!keep) selectVehicle(chosen.id);
}

function selectVehicle(id) {
  releaseControl();
  page.telemetry?.close();
  page.vehicleId = Number(id);
  page.vehicleType = page.vehicles.find((v) => v.id === page.vehicleId)?.type || "";
  page.state = null;
  plots.alt.clear();
  plots.speed.clear();
  page.telemetry = new TelemetrySocket(page.vehicleId, { onMessage: onTelemetry, onStatus: onTelemetryStatus });
  loadParams();
}

// ---- offboard -----------------------------------------------------------------------------

const panel = new SetpointPanel($("sp-fields"), () => scheduleSetpoint());
let sendTimer = null;
let lastSentAt = 0;
let lastSetpointError = "";

function currentBody() {
  return setpointBody(panel.type, panel.values, page.state?.home?.down_m ?? 0);
}

function scheduleSetpoint() {
  if (!inControl()) return;
  const wait = SETPOINT_SEND_INTERVAL_MS - (performance.now() - lastSentAt);
  if (wait <= 0) sendSetpoint();
  else if (!sendTimer) sendTimer = setTimeout(() => { sendTimer = null; sendSetpoint(); }, wait);
}

async function sendSetpoint(body = currentBody()) {
  if (!page.control) return null; // released while a send was scheduled
  lastSentAt = performance.now();
  const answer = await page.control.setpoint(body);
  if (!answer.ok) {
    const text = `setpoint refused — ${describeError(answer.status, answer.body)}`;
    if (text !== lastSetpointError) {
      const el = $("result");
      el.textContent = text;
      el.className = "result bad";
      log("WARNING", text);
    }
    lastSetpointError = text;
  } else {
    lastSetpointError = "";
  }
  return answer;
}

function showSetpointType(type) {
  $("sp-type").value = type;
  panel.show(type, valuesFromState(type, page.state));
}

const keyboard = new KeyboardPilot({
  enabled: () => $("kbd-enable").checked && inControl(),
  speed: () => parseFloat($("kbd-speed").value) || 1,
  onKeys: (text) => setText("kbd-state", `keys: ${text}`),
  onVelocity: (v) => {
    holdBrakingSince = null;
    if (panel.type !== "velocity_body") showSetpointType("velocity_body");
    panel.set(v);
    sendSetpoint(setpointBody("velocity_body", panel.values));
  },
  onHold: () => startHold(),
});

// Space: brake with a zero velocity first, then hold the position where the vehicle stopped,
// so it does not fly back to where the key was pressed.
const HOLD_STOPPED_M_S = 0.3;
const HOLD_BRAKE_TIMEOUT_MS = 5000;
let holdBrakingSince = null;

function startHold() {
  holdBrakingSince = performance.now();
  showSetpointType("velocity");
  sendSetpoint(setpointBody("velocity", panel.values));
  log("NOTICE", "hold: braking, then holding the position where it stops");
}

function continueHold(state) {
  if (holdBrakingSince === null || !inControl()) return;
  const v = state.velocity_ned;
  const speed = v ? Math.hypot(v.north_m_s, v.east_m_s, v.down_m_s) : 0;
  if (speed > HOLD_STOPPED_M_S && performance.now() - holdBrakingSince < HOLD_BRAKE_TIMEOUT_MS) return;
  holdBrakingSince = null;
  showSetpointType("position");
  sendSetpoint();
}

// ---- reposition ---------------------------------------------------------------------------

function offsetLatLon(latDeg, lonDeg, northM, eastM) {
  const dLat = (northM / EARTH_RADIUS_M) * (180 / Math.PI);
  const dLon = (eastM / (EARTH_RADIUS_M * Math.cos((latDeg * Math.PI) / 180))) * (180 / Math.PI);
  return [latDeg + dLat, lonDeg + dLon];
}

function repositionAltitude() {
  const alt = parseFloat($("repo-alt").value);
  if (Number.isFinite(alt)) return alt;
  return altitudeAboveHome(page.state || {}) ?? 10;
}

function reposition(latDeg, lonDeg, label, button) {
  return runCommand(label, "reposition", { lat_deg: latDeg, lon_deg: lonDeg, alt_rel_m: repositionAltitude() }, button);
}

async function pollSceneClick() {
  try {
    const response = await fetch("/scene/api/click", { headers: { Authorization: `Bearer ${token}` } });
    if (!response.ok) return;
    const click = await response.json();
    if (page.lastClickSeq === null) {
      page.lastClickSeq = click.seq;
      return;
    }
    if (click.seq === page.lastClickSeq || !Number.isFinite(click.lat_deg)) return;
    page.lastClickSeq = click.seq;
    $("repo-lat").value = click.lat_deg.toFixed(7);
    $("repo-lon").value = click.lon_deg.toFixed(7);
    const overlay = $("scene-click");
    overlay.textContent = `clicked N ${num(click.north_m)} m, E ${num(click.east_m)} m → ${num(click.lat_deg, 6)}, ${num(click.lon_deg, 6)}`;
    overlay.classList.remove("hidden");
    if ($("repo-on-click").checked && inControl()) reposition(click.lat_deg, click.lon_deg, "Reposition (scene click)");
  } catch {
    // the server is away; the telemetry socket reports that
  }
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

function sceneUrl() {
  return `/scene/?token=${encodeURIComponent(token)}&darkMode`;
}

// The 3D scene renders continuously; switching it off frees the CPU on weak machines.
function showScene(on) {
  $("scene").src = on ? sceneUrl() : "about:blank";
  $("scene").classList.toggle("hidden", !on);
  $("scene-off").classList.toggle("hidden", on);
}

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
  setInterval(loadVehicles, 10000);
  setInterval(pollSceneClick, 1000);
  drawLoop();
  log("INFO", "dashboard ready");
}

main();

// The page's state, for the browser console and the browser tests.
window.skyhelm = { page, SETPOINT_TYPES };
