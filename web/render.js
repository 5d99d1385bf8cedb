// Drawing one state message: the top bar, the telemetry table, the setpoint stream, the
// VTOL progress and the strip charts.

import { followFlown } from "./control.js";
import { Painter, SLOW_BEAT_MS, setAttr, setStyle } from "./draw.js";
import { age, millis } from "./format.js";
import { Instruments } from "./instruments.js";
import { flownText } from "./offboard.js";
import { freshness, page, plots } from "./page.js";
import { $, nowS, num, setText } from "./ui.js";
import { renderSigning } from "./signing.js";

export const instruments = new Instruments($("instruments"), freshness);
// the telemetry table greys out like the instruments (by the age of each value's message)
for (const [id, source] of Object.entries({
  "t-battery": "battery", "t-gps": "gps", "t-pos": "position", "t-vel": "position",
  "t-alt": "altitude", "t-latlon": "altitude", "t-att": "attitude", "t-speed": "speed",
  "t-home": "home", "t-motors": "motors", mode: "mode", armed: "mode", landed: "landed",
  "vtol-state": "landed", "user-mode": "mode", // Wanted: CURRENT_MODE.intended_custom_mode
  "ready-to-fly": "SYS_STATUS",
})) freshness.watch($(id), source, { ownTitle: id === "mode" || id === "ready-to-fly" });
freshness.onRefresh(renderLink);

// Above this age of its freshest message the vehicle is late (amber), before the server's
// verdict says it is lost (red).
const LINK_LATE_S = 1.0;

/** A lost link's age as the LINK box says it: to the second for a minute, then in whole
 * minutes ("LOST · 59 min"), then in whole hours: a pilot needs minutes by then, and the box
 * keeps its width (the tooltip says the age whole). */
export function lostAge(seconds) {
  if (typeof seconds !== "number" || !Number.isFinite(seconds) || seconds < 60) return age(seconds);
  return seconds < 3600 ? `${Math.floor(seconds / 60)} min` : `${Math.floor(seconds / 3600)} h`;
}

/** The LINK box: the server's link to the vehicle, apart from this page's link to the server
 * (SERVER). Its age keeps growing between states, so a silent server shows too: then what
 * the link does is not known (grey). */
function renderLink() {
  const state = page.state;
  if (!state) return;
  const silentS = freshness.freshestS();
  const quality = state.link_quality;
  const pct = (value) => (value === null || value === undefined ? "?" : `${num(value, 0)}%`);
  setText("link-loss", quality ? `↓${pct(quality.loss_in_pct)} ↑${pct(quality.loss_out_pct)}` : "");
  const late = silentS !== null && silentS > LINK_LATE_S;
  // on time it says so; the age to the tenth once late (a live link's age flickers below 1 s)
  const ageText = silentS !== null && !late ? `< ${num(LINK_LATE_S, 0)} s` : age(silentS);
  let text = ageText;
  let cls = late || quality?.degraded ? "warn" : "ok";
  if (state.connected === false) {
    text = `LOST · ${lostAge(silentS)}`;
    cls = "bad";
  } else if (!page.connected) {
    text = `? · ${lostAge(silentS)}`;
    cls = "";
  }
  setText("link-health", text, cls);
  const warnings = quality?.warnings?.length ? `; ${quality.warnings.join("; ")}` : "";
  // the ages in the tooltip as in the box: under a second is on time
  const heartbeatS = state.last_heartbeat_age_s;
  const heartbeat = Number.isFinite(heartbeatS) && heartbeatS <= LINK_LATE_S ? `< ${num(LINK_LATE_S, 0)} s` : age(heartbeatS);
  setAttr($("link-slot"), "title", `the server's link to vehicle ${state.vehicle ?? ""}: its freshest message ${ageText} old`
    + ` (heartbeat ${heartbeat}), frames lost from it ${pct(quality?.loss_in_pct)}`
    + ` and to it ${pct(quality?.loss_out_pct)}${warnings}`
    + (state.lost_reason ? `; lost: ${state.lost_reason}` : "")
    + (page.connected ? "" : "; this page has lost the server, so the link's state is not known"));
}

export function altitudeAboveHome(state) {
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

/** A state came: kept at once (the page's state, the message ages, the plots' samples, also
 * while the page is hidden); drawn by render() at the pace a person can see. */
export function accept(state) {
  page.state = state;
  if (state.vehicle_type) page.vehicleType = state.vehicle_type;
  freshness.update(state);
  plots.add(nowS(), state, {
    alt_above_home_m: [altitudeAboveHome(state), setpointAltitude(state)],
    ground_speed_m_s: [state.ground_speed_m_s, setpointSpeed(state)],
  });
}

// The link badge: lost, or degraded (the warning before the verdict, its reasons on hover),
// with the loss each way from state.link_quality (sequence numbers; "?" where unknown).
export function render(state) {
  const failsafe = state.user_mode && state.user_mode !== state.mode && state.armed;
  setText("mode", state.mode || "–");
  setAttr($("mode"), "title", state.mode || "");
  setStyle($("mode"), "color", failsafe ? "var(--bad)" : state.mode === "OFFBOARD" ? "var(--offboard)" : "");
  setText("user-mode", state.user_mode || "–");
  setText("armed", state.armed ? "ARMED" : "DISARMED", state.armed ? "ok" : "");
  const landedCls = { IN_AIR: "info", TAKEOFF: "warn", LANDING: "warn" }[state.landed_state] || "";
  setText("landed", (state.landed_state || "–").replace("_", " "), landedCls);
  const vtol = Boolean(state.vtol_state && state.vtol_state !== "UNDEFINED");
  toggle($("vtol-state"), "hidden", !vtol);
  if (vtol) {
    // a transition as the VTOL panel says it ("→ FW"), so the badge holds it whole
    const transition = /^TRANSITION_TO_(\w+)$/.exec(state.vtol_state);
    setText("vtol-state", transition ? `→ ${transition[1]}` : state.vtol_state.replaceAll("_", " "), transition ? "warn" : "info");
    setAttr($("vtol-state"), "title", transition ? `in transition to ${transition[1] === "FW" ? "fixed-wing" : "multicopter"} flight` : "");
  }

  renderSigning(state);
  renderTelemetry(state);
  renderStream(state.stream || {});
  renderVtol(state);
  instruments.show(state);
  freshness.refresh();
  const streaming = Boolean(state.stream?.active && state.setpoint);
  setText("sp-flown-text", streaming ? flownText(state.setpoint, state.home?.down_m ?? 0) : "no setpoint streamed");
  setAttr($("sp-flown"), "title", $("sp-flown").textContent);
  followFlown(state);
}

function toggle(el, cls, on) {
  if (el.classList.contains(cls) !== on) el.classList.toggle(cls, on);
}

function renderTelemetry(state) {
  const b = state.battery;
  setText("t-battery", b ? `${num(b.voltage_v, 2)} V · ${num(b.current_a, 1)} A · ${num(b.remaining_pct, 0)}%` : "–");
  if (b && Number.isFinite(b.remaining_pct)) setStyle($("t-battery"), "color", b.remaining_pct < 20 ? "var(--bad)" : b.remaining_pct < 40 ? "var(--warn)" : "");
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
  setStyle($("stream-active"), "color", s.active ? "var(--ok)" : "var(--dim)");
  setText("stream-rate", s.rate_hz ? `${num(s.rate_hz, 1)} Hz` : "–");
  setText("stream-p99", Number.isFinite(s.interval_p99_ms) ? `${num(s.interval_p99_ms, 1)} ms` : "–");
  setText("stream-gap", Number.isFinite(s.max_gap_ms) ? `${num(s.max_gap_ms, 0)} ms` : "–");
  // on time, its running counters at their own pace; a stream that stops or is late at once
  if (s.active && s.since_last_ms <= STREAM_LATE_MS) streamCounters.request();
  else drawStreamCounters(s);
  setStyle($("stream-gap"), "color", s.max_gap_ms > 500 ? "var(--bad)" : s.max_gap_ms > 100 ? "var(--warn)" : "");
  // who sends the frames (the sender process, or the thread after it failed), its restarts
  // and last fault (the stream went on; a "stream" event in the log told when)
  const restarts = s.sender_restarts ? `, ${s.sender_restarts} restart${s.sender_restarts > 1 ? "s" : ""}` : "";
  setText("stream-sender", s.sender ? `${s.sender}${restarts}` : "–");
  setAttr($("stream-sender"), "title", s.sender_fault ? `last fault: ${s.sender_fault}` : "");
  setStyle($("stream-sender"), "color", s.sender_fault && s.sender !== "process" ? "var(--warn)" : "");
}

// The stream's running counters (frames sent, time since the last frame) change with every
// state while it streams, a number read rather than watched: drawn at most twice a second,
// on the plots' beat, while the stream is on time (its last frame at most STREAM_LATE_MS
// ago); at every state while it is stopped or late.
const STREAM_LATE_MS = 100;
const streamCounters = new Painter("stream-counters",
  () => drawStreamCounters(page.state?.stream || {}), { minGapMs: SLOW_BEAT_MS, beatMs: SLOW_BEAT_MS });

function drawStreamCounters(s) {
  setText("stream-since", millis(s.since_last_ms));
  setText("stream-sent", `${s.sent ?? "–"}`);
}

const TRANSITION_GUESS_S = { TRANSITION_TO_FW: 3.5, TRANSITION_TO_MC: 1.5 };

function renderVtol(state) {
  const isVtol = /VTOL/.test(page.vehicleType) || (state.vtol_state && state.vtol_state !== "UNDEFINED");
  toggle($("vtol-panel"), "hidden", !isVtol);
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
  setStyle($("vtol-progress-bar"), "width", `${pct}%`);
  setText("vtol-progress", text || "–");
}
