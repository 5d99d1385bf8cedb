// Manual flying: a gamepad (browser Gamepad API) or two on-screen sticks. While the pilot
// holds control and "Fly with sticks" is on, the stick positions go to the server 25 times a
// second on the control socket; the server sends them to the vehicle as MANUAL_CONTROL on
// its own 25 Hz schedule, centres them when the page goes quiet and then stops (PX4's own
// manual-control-loss failsafe then applies). Mapping and expo are saved in localStorage.
//
// Mode 2 layout: left stick throttle (up/down) and yaw, right stick pitch and roll.
// Positions: pitch forward +, roll right +, yaw clockwise +, each -1..1; throttle 0..1.

import { describeError } from "./api.js";
import { inControl } from "./handover.js";
import { page } from "./page.js";
import { $, log } from "./ui.js";

const SEND_INTERVAL_MS = 40; // 25 Hz, QGroundControl's rate
const GAMEPAD_DEADZONE = 0.05;
const STORAGE_KEY = "skyhelm.sticks";
// Modes where the throttle stick stays where it is let go (it is thrust or a climb rate the
// pilot sets); in POSCTL it springs back to the middle, which holds the altitude.
const THROTTLE_HOLD_MODES = new Set(["ALTCTL", "STABILIZED", "MANUAL", "ACRO"]);
const AXES = ["throttle", "yaw", "pitch", "roll"];
// Standard gamepad: left stick axes 0 (x) and 1 (y, up is -1), right stick 2 and 3.
const DEFAULT_SETTINGS = {
  expo: 0.0, // the page's own curve; PX4 adds its MPC_*_EXPO on top
  throttleHold: "auto", // "auto" (by mode), "always", "never"
  gamepad: {
    throttle: { axis: 1, invert: true },
    yaw: { axis: 0, invert: false },
    pitch: { axis: 3, invert: true },
    roll: { axis: 2, invert: false },
  },
};

export function loadSettings() {
  try {
    const saved = JSON.parse(localStorage.getItem(STORAGE_KEY) || "{}");
    return {
      ...DEFAULT_SETTINGS,
      ...saved,
      gamepad: { ...DEFAULT_SETTINGS.gamepad, ...(saved.gamepad || {}) },
    };
  } catch {
    return structuredClone(DEFAULT_SETTINGS);
  }
}

function saveSettings(settings) {
  localStorage.setItem(STORAGE_KEY, JSON.stringify(settings));
}

const clamp = (x, lo, hi) => Math.min(hi, Math.max(lo, x));

/** PX4's expo curve: linear at 0, cubic at 1. */
export function expo(x, e) {
  const v = clamp(x, -1, 1);
  return (1 - e) * v + e * v * v * v;
}

/** One on-screen stick: a pad with a knob the pointer drags; x and y in -1..1 (y up +). */
class VirtualStick {
  constructor(pad, { holdY = () => false } = {}) {
    this.pad = pad;
    this.knob = pad.querySelector(".stick-knob");
    this.holdY = holdY;
    this.x = 0;
    this.y = 0;
    this.pointer = null;
    pad.addEventListener("pointerdown", (e) => this.grab(e));
    pad.addEventListener("pointermove", (e) => this.move(e));
    pad.addEventListener("pointerup", (e) => this.release(e));
    pad.addEventListener("pointercancel", (e) => this.release(e));
    this.draw();
  }

  grab(event) {
    if (this.pointer !== null) return;
    this.pointer = event.pointerId;
    this.pad.setPointerCapture(event.pointerId);
    this.pad.classList.add("held");
    this.move(event);
    event.preventDefault();
  }

  move(event) {
    if (event.pointerId !== this.pointer) return;
    const box = this.pad.getBoundingClientRect();
    const half = box.width / 2;
    this.x = clamp((event.clientX - (box.left + half)) / half, -1, 1);
    this.y = clamp(((box.top + box.height / 2) - event.clientY) / (box.height / 2), -1, 1);
    this.draw();
  }

  release(event) {
    if (event.pointerId !== this.pointer) return;
    this.pointer = null;
    this.pad.classList.remove("held");
    // springs back to the middle; the throttle axis may stay where it was let go
    this.x = 0;
    if (!this.holdY()) this.y = 0;
    this.draw();
  }

  centre() {
    this.x = 0;
    this.y = 0;
    this.draw();
  }

  draw() {
    this.knob.style.left = `${50 + this.x * 42}%`;
    this.knob.style.top = `${50 - this.y * 42}%`;
  }
}

function buildPanel(root) {
  root.innerHTML = `
    <h2>Sticks <span id="sticks-source" class="badge">off</span></h2>
    <div class="row">
      <label><input id="sticks-enable" type="checkbox"> Fly with sticks</label>
      <button id="sticks-posctl" class="ctl" title="Position mode: sticks fly velocities, centred holds">Position mode</button>
    </div>
    <div class="sticks-pads">
      <div id="stick-left" class="stick-pad" title="throttle (up/down) and yaw"><div class="stick-knob"></div><span class="stick-label">throttle · yaw</span></div>
      <div id="stick-right" class="stick-pad" title="pitch (forward/back) and roll"><div class="stick-knob"></div><span class="stick-label">pitch · roll</span></div>
    </div>
    <div id="sticks-values" class="hint">–</div>
    <div class="hint">Stopping the sticks in flight is a lost transmitter for PX4: Hold, then Return (NAV_RCL_ACT), unless COM_RCL_EXCEPT exempts the mode.</div>
    <details class="sticks-settings"><summary>Mapping and expo</summary>
      <div class="row small"><label class="field">expo <input id="sticks-expo" type="range" min="0" max="1" step="0.05"></label><b id="sticks-expo-value"></b></div>
      <div class="row small"><label class="field">throttle stick
        <select id="sticks-throttle-hold"><option value="auto">holds in Altitude/Stabilized</option><option value="always">always holds</option><option value="never">springs back</option></select></label></div>
      <div id="sticks-mapping"></div>
      <div class="hint">gamepad axes: ${AXES.map((a) => a).join(", ")} — axis number and invert</div>
    </details>`;
}

function buildMapping(settings, onChange) {
  const box = $("sticks-mapping");
  box.innerHTML = "";
  for (const name of AXES) {
    const row = document.createElement("div");
    row.className = "row small";
    row.innerHTML = `<label class="field">${name} axis <input class="num" type="number" min="0" max="15" step="1" data-axis="${name}"></label>
      <label><input type="checkbox" data-invert="${name}"> invert</label>`;
    const axis = row.querySelector(`[data-axis="${name}"]`);
    const invert = row.querySelector(`[data-invert="${name}"]`);
    axis.value = settings.gamepad[name].axis;
    invert.checked = settings.gamepad[name].invert;
    axis.addEventListener("change", () => {
      settings.gamepad[name] = { ...settings.gamepad[name], axis: parseInt(axis.value, 10) || 0 };
      onChange();
    });
    invert.addEventListener("change", () => {
      settings.gamepad[name] = { ...settings.gamepad[name], invert: invert.checked };
      onChange();
    });
    box.appendChild(row);
  }
}

function firstGamepad() {
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  for (const pad of pads || []) if (pad && pad.connected !== false && pad.axes?.length >= 4) return pad;
  return null;
}

// A page listening for gamepads makes the browser poll for them (Chromium: a thread in the
// browser process, about 1 % of a core, for as long as any page listens). A hidden page gets
// no gamepad events anyway (the API serves the visible page only), so it stops listening
// while hidden and listens again when shown.
const connected = (e) => log("INFO", `gamepad connected: ${e.gamepad.id}`);
const disconnected = (e) => log("WARNING", `gamepad disconnected: ${e.gamepad.id}`);

function listenForGamepads() {
  const follow = () => {
    const listen = document.visibilityState !== "hidden" ? window.addEventListener : window.removeEventListener;
    listen.call(window, "gamepadconnected", connected);
    listen.call(window, "gamepaddisconnected", disconnected);
  };
  follow();
  document.addEventListener("visibilitychange", follow);
}

function gamepadAxis(pad, mapping) {
  const raw = pad.axes[mapping.axis] ?? 0;
  const v = Math.abs(raw) < GAMEPAD_DEADZONE ? 0 : raw;
  return mapping.invert ? -v : v;
}

export class StickPilot {
  constructor(root) {
    buildPanel(root);
    this.settings = loadSettings();
    this.enabled = false;
    this.timer = null;
    this.lastError = "";
    this.sent = 0;
    this.left = new VirtualStick($("stick-left"), { holdY: () => this.throttleHolds() });
    this.right = new VirtualStick($("stick-right"));
    this.wire();
  }

  throttleHolds() {
    const hold = this.settings.throttleHold;
    if (hold === "always") return true;
    if (hold === "never") return false;
    return THROTTLE_HOLD_MODES.has(page.state?.mode);
  }

  wire() {
    const expoInput = $("sticks-expo");
    const expoValue = $("sticks-expo-value");
    const showExpo = () => { expoValue.textContent = Number(this.settings.expo).toFixed(2); };
    expoInput.value = this.settings.expo;
    showExpo();
    expoInput.addEventListener("input", () => {
      this.settings.expo = parseFloat(expoInput.value) || 0;
      showExpo();
      saveSettings(this.settings);
    });
    const hold = $("sticks-throttle-hold");
    hold.value = this.settings.throttleHold;
    hold.addEventListener("change", () => {
      this.settings.throttleHold = hold.value;
      saveSettings(this.settings);
    });
    buildMapping(this.settings, () => saveSettings(this.settings));
    $("sticks-enable").addEventListener("change", (e) => this.setEnabled(e.target.checked));
    $("sticks-posctl").addEventListener("click", () => this.positionMode());
    listenForGamepads();
  }

  /** What the pilot's hands say now: the gamepad when one is connected, else the screen. */
  read() {
    const pad = firstGamepad();
    const e = this.settings.expo;
    let throttleY, yaw, pitch, roll, source;
    if (pad) {
      const map = this.settings.gamepad;
      throttleY = gamepadAxis(pad, map.throttle);
      yaw = gamepadAxis(pad, map.yaw);
      pitch = gamepadAxis(pad, map.pitch);
      roll = gamepadAxis(pad, map.roll);
      source = `gamepad: ${pad.id || "unnamed"}`;
    } else {
      throttleY = this.left.y;
      yaw = this.left.x;
      pitch = this.right.y;
      roll = this.right.x;
      source = "on-screen";
    }
    return {
      source,
      sticks: {
        pitch: round3(expo(pitch, e)),
        roll: round3(expo(roll, e)),
        yaw: round3(expo(yaw, e)),
        throttle: round3(clamp((throttleY + 1) / 2, 0, 1)),
      },
    };
  }

  setEnabled(on) {
    if (on && !inControl()) on = false; // only the pilot in control flies
    if (on === this.enabled) {
      $("sticks-enable").checked = on;
      return;
    }
    this.enabled = on;
    $("sticks-enable").checked = on;
    clearInterval(this.timer);
    this.timer = null;
    if (on) {
      this.left.centre();
      this.right.centre();
      this.timer = setInterval(() => this.tick(), SEND_INTERVAL_MS);
    } else {
      if (inControl()) page.control.send({ type: "sticks", stop: true });
      this.show("off", null);
    }
  }

  async tick() {
    if (!inControl()) {
      this.setEnabled(false); // control lost or released: stop at once
      return;
    }
    const { source, sticks } = this.read();
    this.show(source, sticks);
    this.sent += 1;
    const answer = await page.control.send({ type: "sticks", sticks });
    if (!answer.ok) {
      const text = `sticks refused — ${describeError(answer.status, answer.body)}`;
      if (text !== this.lastError) log("WARNING", text);
      this.lastError = text;
    } else {
      this.lastError = "";
    }
  }

  show(source, sticks) {
    const badge = $("sticks-source");
    badge.textContent = this.enabled ? source : "off";
    badge.className = `badge ${this.enabled && sticks ? "ok" : ""}`;
    $("sticks-values").textContent = sticks
      ? `pitch ${sticks.pitch.toFixed(2)} · roll ${sticks.roll.toFixed(2)} · yaw ${sticks.yaw.toFixed(2)} · throttle ${sticks.throttle.toFixed(2)}`
      : "–";
  }

  async positionMode() {
    if (!inControl()) return;
    this.setEnabled(true);
    // PX4 refuses Position without stick input: let some reach it first
    await new Promise((resolve) => setTimeout(resolve, 3 * SEND_INTERVAL_MS));
    const answer = await page.control.command("mode", { mode: "POSCTL" });
    log(answer.ok ? "OK" : "ERROR", answer.ok ? "Position mode" : `Position mode refused — ${describeError(answer.status, answer.body)}`);
  }
}

const round3 = (x) => Math.round(x * 1000) / 1000;

const root = $("sticks-panel");
export const sticks = root ? new StickPilot(root) : null;
if (sticks) window.skyhelm = { ...(window.skyhelm || {}), sticks };
