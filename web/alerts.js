// Alerts a pilot must not miss: link lost, failsafe, low battery, geofence, control taken.
// Each is a banner that stays while its condition holds, is spoken (speechSynthesis, as
// QGroundControl speaks), can be muted (remembered in localStorage), and is dispatched as a
// "skyhelm-alert" DOM event and kept in `alertLog`, so what was said can be checked.

import { num } from "./format.js";

const MUTE_KEY = "skyhelm.alerts.muted";
// PX4's default thresholds (BAT_LOW_THR, BAT_CRIT_THR) as percentages
const BAT_LOW_PCT = 15;
const BAT_CRIT_PCT = 7;
const BAT_CLEAR_MARGIN_PCT = 2;
const TEXT_ALERT_MS = 15000; // an alert from a message (no condition to watch) shows this long
const ALERT_LOG_LIMIT = 200;

export const alertLog = []; // {kind, text, level, spoken, time}

function storedMute() {
  try {
    return localStorage.getItem(MUTE_KEY) === "1";
  } catch {
    return false;
  }
}

export class Alerts {
  constructor(container, muteButton) {
    this.container = container;
    this.muteButton = muteButton;
    this.active = new Map(); // kind -> {element, text, level, timer}
    this.muted = storedMute();
    this.vehicleLost = false;
    this.lastMode = null;
    this.showMute();
    muteButton.addEventListener("click", () => this.setMuted(!this.muted));
  }

  setMuted(muted) {
    this.muted = muted;
    try {
      localStorage.setItem(MUTE_KEY, muted ? "1" : "0");
    } catch {
      // private mode: muted for this visit only
    }
    if (muted) window.speechSynthesis?.cancel?.();
    this.showMute();
  }

  showMute() {
    this.muteButton.textContent = this.muted ? "Sound: muted" : "Sound: on";
    this.muteButton.title = this.muted ? "alerts are not spoken: click to speak them" : "alerts are spoken: click to mute";
    this.muteButton.classList.toggle("muted", this.muted);
    this.muteButton.setAttribute("aria-pressed", String(this.muted));
  }

  /** Shows, speaks and records an alert; one of a kind at a time (a repeat only updates it). */
  raise(kind, text, level = "warning", { forMs = 0 } = {}) {
    const shown = this.active.get(kind);
    if (shown) {
      if (shown.text !== text) shown.element.querySelector("span").textContent = text;
      if (shown.level !== level) shown.element.className = `alert ${level}`;
      Object.assign(shown, { text, level });
      this.timeOut(kind, shown, forMs);
      return;
    }
    const element = document.createElement("div");
    element.className = `alert ${level}`;
    element.dataset.kind = kind;
    element.setAttribute("role", level === "critical" ? "alert" : "status");
    const words = document.createElement("span");
    words.textContent = text;
    const close = document.createElement("button");
    close.textContent = "×";
    close.title = "dismiss (it comes back if it happens again)";
    close.addEventListener("click", () => this.clear(kind));
    element.append(words, close);
    this.container.append(element);
    const entry = { element, text, level, timer: null };
    this.active.set(kind, entry);
    this.timeOut(kind, entry, forMs);
    const spoken = this.speak(text);
    const record = { kind, text, level, spoken, time: Date.now() };
    alertLog.push(record);
    if (alertLog.length > ALERT_LOG_LIMIT) alertLog.shift();
    document.dispatchEvent(new CustomEvent("skyhelm-alert", { detail: record }));
  }

  timeOut(kind, entry, forMs) {
    clearTimeout(entry.timer);
    entry.timer = forMs ? setTimeout(() => this.clear(kind), forMs) : null;
  }

  clear(kind) {
    const shown = this.active.get(kind);
    if (!shown) return;
    clearTimeout(shown.timer);
    shown.element.remove();
    this.active.delete(kind);
  }

  clearAll() {
    for (const kind of [...this.active.keys()]) this.clear(kind);
  }

  speak(text) {
    if (this.muted) return false;
    const synth = window.speechSynthesis;
    if (!synth || typeof window.SpeechSynthesisUtterance !== "function") return false;
    try {
      synth.speak(new window.SpeechSynthesisUtterance(text));
      return true;
    } catch {
      return false;
    }
  }

  // ---- sources ------------------------------------------------------------------------------

  /** Conditions read from each state: link, failsafe, battery. */
  fromState(state) {
    const name = `vehicle ${state.vehicle ?? state.id ?? ""}`.trim();
    if (state.connected === false) {
      this.vehicleLost = true;
      // and how the server noticed: its silence, or the simulated vehicle's process ended
      const how = state.lost_reason ? ` — ${state.lost_reason}` : "";
      this.raise("link", `Link lost with ${name}${how}`, "critical");
    } else if (state.connected) {
      if (this.vehicleLost) this.raise("link-back", `Link with ${name} regained`, "info", { forMs: 5000 });
      this.vehicleLost = false;
      this.clear("link");
    }
    const failsafe = state.armed && state.user_mode && state.mode && state.user_mode !== state.mode;
    // back in the chosen mode (or disarmed): a failsafe the vehicle announced is over too
    const recovered = !state.armed || (state.mode === state.user_mode && state.mode !== this.lastMode);
    if (failsafe) this.raise("failsafe", `Failsafe: ${words(state.mode)}`, "critical");
    else if (!this.active.get("failsafe")?.fromText || recovered) this.clear("failsafe");
    this.lastMode = state.mode;
    const pct = state.battery?.remaining_pct;
    if (Number.isFinite(pct)) {
      if (pct <= BAT_CRIT_PCT) {
        this.clear("battery-low");
        this.raise("battery-critical", `Battery critical: ${num(pct, 0)} percent`, "critical");
      } else if (pct <= BAT_LOW_PCT) {
        this.raise("battery-low", `Low battery: ${num(pct, 0)} percent`, "warning");
      } else if (pct > BAT_LOW_PCT + BAT_CLEAR_MARGIN_PCT) {
        this.clear("battery-low");
        this.clear("battery-critical");
      }
    }
  }

  /** The vehicle's messages: geofence breaches and failsafes it announces. */
  fromText(severity, text) {
    if (/geofence|geo-fence/i.test(text)) {
      this.raise("geofence", text, "critical", { forMs: TEXT_ALERT_MS });
    } else if (/failsafe/i.test(text) && /^(EMERGENCY|ALERT|CRITICAL|ERROR|WARNING)$/.test(severity)) {
      this.raise("failsafe", text, "critical", { forMs: TEXT_ALERT_MS });
      this.active.get("failsafe").fromText = true;
    }
  }

  /** The server connection of the page; `retryInS`: when the page tries again. */
  fromServer(connected, retryInS = 0) {
    if (connected) this.clear("server");
    else this.raise("server", `Connection to the server lost${retryInS ? ` — trying again in ${retryInS} s` : " — trying again…"}`, "critical");
  }

  /** This tab lost control to someone else. */
  controlTaken(by) {
    this.raise("control", `Control taken by ${by}`, "warning", { forMs: TEXT_ALERT_MS });
  }
}

function words(mode) {
  return String(mode).toLowerCase().replaceAll("_", " ");
}
