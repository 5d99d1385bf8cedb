// Flying from the page: the control lease, commands and their answers, setpoints from the
// panel and the keyboard, reposition.

import { ControlSession, describeError } from "./api.js";
import { KeyboardPilot, SetpointPanel, setpointBody, valuesFromState } from "./offboard.js";
import { page } from "./page.js";
import { altitudeAboveHome } from "./render.js";
import { $, log, num, setText } from "./ui.js";

const SETPOINT_SEND_INTERVAL_MS = 50;
const CONFIRM_WINDOW_MS = 4000;
const EARTH_RADIUS_M = 6378137;
const RETAKE_DELAY_MS = 1000;

// ---- command answers ----------------------------------------------------------------------

export function showResult(label, answer) {
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

export async function runCommand(label, name, args, button) {
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

export function confirmThen(button, action) {
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

export function takeControl(takeover = false) {
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

export function releaseControl() {
  page.wantControl = false;
  page.control?.close();
  page.control = null;
  updateControls();
}

export function inControl() {
  return Boolean(page.control && page.control.open);
}

export function renderHolder(holder) {
  const mine = inControl();
  setText("holder", mine ? `you (${page.control.holder || holder || "this page"})` : holder || "nobody");
}

export function updateControls() {
  const pilot = inControl() && page.connected;
  document.body.classList.toggle("observing", !pilot);
  for (const el of document.querySelectorAll(".ctl")) el.disabled = !pilot;
  $("take-control").classList.toggle("hidden", inControl() || page.readOnly);
  $("release").classList.toggle("hidden", !inControl());
  renderHolder(page.state?.lease?.holder);
}

// ---- offboard -----------------------------------------------------------------------------

export const panel = new SetpointPanel($("sp-fields"), () => scheduleSetpoint());
let sendTimer = null;
let lastSentAt = 0;
let lastSetpointError = "";

export function currentBody() {
  return setpointBody(panel.type, panel.values, page.state?.home?.down_m ?? 0);
}

function scheduleSetpoint() {
  if (!inControl()) return;
  const wait = SETPOINT_SEND_INTERVAL_MS - (performance.now() - lastSentAt);
  if (wait <= 0) sendSetpoint();
  else if (!sendTimer) sendTimer = setTimeout(() => { sendTimer = null; sendSetpoint(); }, wait);
}

export async function sendSetpoint(body = currentBody()) {
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

export function showSetpointType(type) {
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

export function continueHold(state) {
  if (holdBrakingSince === null || !inControl()) return;
  const v = state.velocity_ned;
  const speed = v ? Math.hypot(v.north_m_s, v.east_m_s, v.down_m_s) : 0;
  if (speed > HOLD_STOPPED_M_S && performance.now() - holdBrakingSince < HOLD_BRAKE_TIMEOUT_MS) return;
  holdBrakingSince = null;
  showSetpointType("position");
  sendSetpoint();
}

// ---- reposition ---------------------------------------------------------------------------

export function offsetLatLon(latDeg, lonDeg, northM, eastM) {
  const dLat = (northM / EARTH_RADIUS_M) * (180 / Math.PI);
  const dLon = (eastM / (EARTH_RADIUS_M * Math.cos((latDeg * Math.PI) / 180))) * (180 / Math.PI);
  return [latDeg + dLat, lonDeg + dLon];
}

function repositionAltitude() {
  const alt = parseFloat($("repo-alt").value);
  if (Number.isFinite(alt)) return alt;
  return altitudeAboveHome(page.state || {}) ?? 10;
}

export function reposition(latDeg, lonDeg, label, button) {
  return runCommand(label, "reposition", { lat_deg: latDeg, lon_deg: lonDeg, alt_rel_m: repositionAltitude() }, button);
}
