// Flying from the page: commands and their answers, setpoints from the panel, and the
// intents the server flies (keyboard velocity, brake, go by an offset, go to a point). The
// page decides nothing about how they are flown: it sends them and shows the answers.

import { AltitudeGuard, altitudeAboveHomeM } from "./altitude-guard.js";
import { describeError } from "./api.js";
import { confirmAction } from "./confirm.js";
import { inControl, onControl } from "./handover.js";
import {
  KeyboardPilot, SetpointPanel, moveText, panelForSetpoint, panelMessage, valuesFromState,
} from "./offboard.js";
import { page } from "./page.js";
import { $, log, num, setText } from "./ui.js";

const SETPOINT_SEND_INTERVAL_MS = 50;
const CONFIRM_WINDOW_MS = 4000;

// ---- command answers ----------------------------------------------------------------------

function showLine(text, cls) {
  const el = $("result");
  el.textContent = text;
  el.className = `result ${cls}`;
}

export function showResult(label, answer) {
  const body = answer.body || {};
  const command = body.command && typeof body.command === "object" ? body.command : body;
  let text;
  if (answer.ok) {
    const elapsed = command.elapsed_ms !== undefined ? ` (${num(command.elapsed_ms, 0)} ms)` : "";
    const result = command.result || (body.via ? `OK via ${body.via.replace("_", " ")}` : "OK");
    text = `${label}: ${result}${elapsed}${command.reason ? ` — ${command.reason}` : ""}`;
  } else if (command.result) {
    text = `${label}: ${command.result}${command.reason ? ` — ${command.reason}` : ""}`;
  } else {
    text = `${label}: refused — ${describeError(answer.status, body)}`;
  }
  showLine(text, answer.ok ? "ok" : "bad");
  log(answer.ok ? "OK" : "ERROR", text);
}

/** Sends a command or an intent on the control socket and shows the vehicle's answer. */
export async function runCommand(label, name, args, button) {
  if (!page.control) return null;
  showLine(`${label}: sent, waiting for the vehicle…`, "pending");
  button?.classList.add("busy");
  try {
    const answer = await page.control.command(name, args);
    showResult(label, answer);
    if (answer.ok) showFlown(answer.body?.setpoint?.setpoint);
    return answer;
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

// ---- offboard panel -----------------------------------------------------------------------

export const panel = new SetpointPanel($("sp-fields"), () => {
  scheduleSetpoint();
  showMove(page.state);
}, () => askHeld());
// every target that changes an airborne vehicle's altitude much is asked about once
export const altitudeGuard = new AltitudeGuard(confirmAction);
let sendTimer = null;
let lastSentAt = 0;
let lastSetpointError = "";
// the panel's values wait for the pilot's answer to the altitude question before being sent
let held = false;

const homeDownM = () => page.state?.home?.down_m ?? 0;

export function currentMessage() {
  return panelMessage(panel.type, panel.values, homeDownM());
}

/** The altitude above home the panel asks for (position panel only), or NaN. */
function panelAltitudeM() {
  return panel.type === "position" ? panel.values.alt_m : NaN;
}

/** An edit is done: a held altitude is asked about now; confirmed, it is sent, otherwise
 * the altitude follows the vehicle again. */
async function askHeld() {
  if (!held || !inControl()) return;
  const ok = await altitudeGuard.allows(page.state, panelAltitudeM());
  if (!held) return;
  held = false;
  answerNote(ok);
  if (!ok) {
    panel.followAgain(["alt_m"]);
    followFlown(page.state);
    log("NOTICE", "altitude change cancelled: the altitude follows the vehicle again");
  }
  scheduleSetpoint();
}

const NOTE_TAIL = " — asked when you leave the field or let go of the slider";

/** The note that a question is to come gets its answer once it is given (unless the line
 * shows something else by then). */
function answerNote(ok) {
  const shown = $("result").textContent;
  if (!shown.endsWith(NOTE_TAIL)) return;
  const asked = shown.slice(0, -NOTE_TAIL.length).replace(/\?$/, "");
  showLine(`${asked}: ${ok ? "confirmed" : "cancelled"}`, ok ? "ok" : "bad");
}

function scheduleSetpoint() {
  if (!inControl()) return;
  const question = altitudeGuard.question(page.state, panelAltitudeM());
  if (question) {
    // the note names the value the panel shows now, not the one that first needed asking
    const note = `${question.title}${NOTE_TAIL}`;
    if ($("result").textContent !== note) showLine(note, "pending");
    held = true;
    return;
  }
  held = false;
  const wait = SETPOINT_SEND_INTERVAL_MS - (performance.now() - lastSentAt);
  if (wait <= 0) sendPanel();
  else if (!sendTimer) sendTimer = setTimeout(() => { sendTimer = null; sendPanel(); }, wait);
}

/** Sends what the panel shows: its setpoint, or its intent. */
export async function sendPanel(message = currentMessage()) {
  if (!inControl()) return null; // control lost or released while a send was scheduled
  lastSentAt = performance.now();
  const answer = message.intent
    ? await page.control.command(message.intent, message.args)
    : await page.control.setpoint(message.setpoint);
  showRefusal(answer, message.intent ? `${message.intent} refused` : "setpoint refused");
  return answer;
}

function showRefusal(answer, what) {
  if (!answer.ok) {
    const text = `${what} — ${describeError(answer.status, answer.body)}`;
    if (text !== lastSetpointError) {
      showLine(text, "bad");
      log("WARNING", text);
    }
    lastSetpointError = text;
  } else {
    lastSetpointError = "";
  }
}

export function showSetpointType(type) {
  $("sp-type").value = type;
  held = false;
  panel.show(type, valuesFromState(type, page.state));
  followFlown(page.state);
}

/** The fields follow the vehicle again, all of them (the Follow button). */
export function followAgain() {
  held = false;
  panel.followAgain();
  followFlown(page.state);
}

/** Shows a setpoint the vehicle flies (the lease's, or an answer's) in the panel. */
function showFlown(setpoint) {
  const shown = panelForSetpoint(setpoint, homeDownM());
  if (!shown) return false;
  if (shown.type === panel.type) {
    panel.set(shown.values);
  } else {
    $("sp-type").value = shown.type;
    panel.show(shown.type, { ...valuesFromState(shown.type, page.state), ...shown.values });
  }
  return true;
}

/** The panel follows the vehicle: while observing, the setpoint it flies (from the state),
 * not the form's defaults; in control, the fields the pilot has not edited follow the
 * setpoint flown when it is of the panel's kind, else where the vehicle is. The line under
 * it says the move the panel asks for, from where the vehicle is now. */
export function followFlown(state) {
  if (!state) return;
  const streaming = state.stream?.active;
  if (!inControl() && streaming && showFlown(state.setpoint)) {
    showMove(state);
    return;
  }
  const flown = streaming ? panelForSetpoint(state.setpoint, homeDownM()) : null;
  panel.follow(flown && flown.type === panel.type ? flown.values : valuesFromState(panel.type, state));
  showMove(state);
}

function showMove(state) {
  const text = moveText(panel.type, panel.values, state);
  setText("sp-move-text", text || "–");
  const edited = panel.anyEdited();
  setText("sp-follow", edited ? "edited" : "following the vehicle", edited ? "warn" : "");
}

/** Starts OFFBOARD with the panel's setpoint (an intent panel sends its intent first). */
export async function startOffboard(button) {
  if (!(await altitudeGuard.allows(page.state, panelAltitudeM()))) {
    showLine("Start offboard: cancelled", "bad");
    return;
  }
  held = false;
  const message = currentMessage();
  if (message.intent) {
    const answer = await sendPanel(message);
    if (!answer?.ok) return;
    await runCommand("Start offboard", "offboard_start", {}, button);
  } else {
    await runCommand("Start offboard", "offboard_start", { setpoint: message.setpoint }, button);
  }
}

// ---- keyboard: velocity intents, brake ------------------------------------------------------

export const keyboard = new KeyboardPilot({
  enabled: () => $("kbd-enable").checked && inControl(),
  speed: () => parseFloat($("kbd-speed").value) || 1,
  onKeys: (text) => setText("kbd-state", `keys: ${text}`),
  onVelocity: async (v) => {
    const answer = await page.control.command("velocity", { frame: "body", ...v });
    showRefusal(answer, "velocity refused");
    if (answer.ok) showFlown(answer.body?.setpoint?.setpoint);
  },
  onBrake: () => brake(),
});

/** Brake, then hold where the vehicle stopped (the server decides how). */
export function brake(button) {
  return runCommand("Brake", "brake", {}, button);
}

// Control gained: show what the vehicle flies, not the form's defaults. Lost: stop sending.
onControl({
  gained: (lease) => {
    clearTimeout(sendTimer);
    sendTimer = null;
    held = false;
    altitudeGuard.forget();
    const flying = lease.setpoint ?? (page.state?.stream?.active ? page.state.setpoint : null);
    if (!showFlown(flying)) panel.show(panel.type, valuesFromState(panel.type, page.state));
  },
  lost: () => {
    clearTimeout(sendTimer);
    sendTimer = null;
    keyboard.stop();
  },
  change: () => {},
});

// ---- reposition ---------------------------------------------------------------------------

function repositionAltitude() {
  const alt = parseFloat($("repo-alt").value);
  return Number.isFinite(alt) ? alt : null;
}

/** Asks first when a target altitude above home needs it (altitude-guard.js); false when
 * the pilot did not confirm. */
export async function altitudeAllowed(label, targetM) {
  const ok = await altitudeGuard.allows(page.state, targetM);
  if (!ok) showLine(`${label}: cancelled`, "bad");
  return ok;
}

export async function goTo(latDeg, lonDeg, label, button) {
  const alt = repositionAltitude();
  if (alt !== null && !(await altitudeAllowed(label, alt))) return null;
  return runCommand(label, "goto", { lat_deg: latDeg, lon_deg: lonDeg, alt_rel_m: alt }, button);
}

export async function goByOffset(button) {
  const north = parseFloat($("repo-north").value) || 0;
  const east = parseFloat($("repo-east").value) || 0;
  const up = parseFloat($("repo-up").value) || 0;
  const label = `Go ${north} m N ${east} m E ${up} m up`;
  if (!(await altitudeAllowed(label, altitudeAboveHomeM(page.state) + up))) return null;
  return runCommand(label, "offset", { north_m: north, east_m: east, up_m: up }, button);
}
