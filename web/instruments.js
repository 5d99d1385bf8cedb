// The pilot's instruments, drawn in SVG from each state message: attitude indicator (horizon,
// pitch ladder, roll scale), heading tape, altitude / airspeed / vertical speed in big numbers,
// battery with time left, GPS and estimator health, VTOL state.
//
// Truth at a glance: every value is as old as the MAVLink message it came from. The state
// carries each source message's age (message_ages_s); the page adds the time since that state
// came, so ages keep growing while nothing arrives (a paused vehicle, a lost server), and a
// value past its message's limit greys out and shows its age.

import { pageHidden, setAttr, setStyle } from "./draw.js";
import { UNKNOWN, age, duration, heading, num, signed, withUnit, words } from "./format.js";

const SVG = "http://www.w3.org/2000/svg";

// The messages each value comes from (the freshest one counts).
export const SOURCES = {
  attitude: ["ATTITUDE"],
  heading: ["VFR_HUD", "GLOBAL_POSITION_INT", "ATTITUDE"],
  speed: ["VFR_HUD"],
  altitude: ["GLOBAL_POSITION_INT"],
  position: ["LOCAL_POSITION_NED"],
  battery: ["BATTERY_STATUS", "SYS_STATUS"],
  gps: ["GPS_RAW_INT"],
  estimator: ["ESTIMATOR_STATUS"],
  landed: ["EXTENDED_SYS_STATE"],
  mode: ["HEARTBEAT", "CURRENT_MODE"],
  home: ["HOME_POSITION"],
  motors: ["SERVO_OUTPUT_RAW", "ACTUATOR_OUTPUT_STATUS"],
};
// Older than this (s) a message is stale: a few of its periods as PX4 streams it to a GCS.
const STALE_AFTER_S = {
  HEARTBEAT: 3.5, CURRENT_MODE: 3.5, SYS_STATUS: 5, BATTERY_STATUS: 6.5, GPS_RAW_INT: 5,
  ESTIMATOR_STATUS: 5, EXTENDED_SYS_STATE: 5, HOME_POSITION: Infinity,
};
const STALE_DEFAULT_S = 2;
const AGE_TICK_MS = 250;

/** The age an element carries: once stale, to the tenth of a second (it shows then); while
 * fresh, only that it is, so a fresh value is not redrawn four times a second for an age
 * nobody sees. */
const FRESH = "fresh";
function shownAge(ageS, stale) {
  return stale ? age(ageS) : FRESH;
}

/** How old each value of the last state is now, and whether it is stale. */
export class Freshness {
  constructor() {
    this.ages = {};
    this.receivedMs = performance.now();
    this.watched = []; // [element, source key]
    this.linkLost = false;
    this.listeners = [];
    // ages grow between states; a hidden page shows none (refreshed when drawn again)
    this.timer = setInterval(() => { if (!pageHidden()) this.refresh(); }, AGE_TICK_MS);
  }

  /** A state came: its message ages from now on (drawn by the next refresh()). */
  update(state) {
    this.ages = state.message_ages_s || {};
    // the server's verdict: nothing valid comes from the vehicle, whatever each age says yet
    this.linkLost = state.connected === false;
    this.receivedMs = performance.now();
  }

  /** Seconds since anything at all came from the vehicle (its freshest message); null if
   * nothing ever did. */
  freshestS() {
    const known = Object.values(this.ages).filter(Number.isFinite);
    return known.length ? Math.min(...known) + (performance.now() - this.receivedMs) / 1000 : null;
  }

  /** Seconds since the freshest source of `key` was received; null if none ever was. */
  ageOf(key) {
    const elapsedS = (performance.now() - this.receivedMs) / 1000;
    let best = null;
    let limit = STALE_DEFAULT_S;
    for (const kind of SOURCES[key] || [key]) {
      const a = this.ages[kind];
      if (!Number.isFinite(a)) continue;
      if (best === null || a < best) {
        best = a;
        limit = STALE_AFTER_S[kind] ?? STALE_DEFAULT_S;
      }
    }
    if (best === null) return null;
    return { ageS: best + elapsedS, stale: (this.linkLost && limit !== Infinity) || best + elapsedS > limit };
  }

  /** Grey out `element` (and show its age) whenever the value `key` is stale; its tooltip
   * says the age too unless `ownTitle` (another part of the page writes that tooltip). */
  watch(element, key, { ownTitle = false } = {}) {
    element.dataset.src = key;
    this.watched.push([element, key, ownTitle]);
  }

  /** `listener()` runs at every refresh: at each state and as ages grow between states. */
  onRefresh(listener) {
    this.listeners.push(listener);
  }

  refresh() {
    for (const listener of this.listeners) listener();
    for (const [element, key, ownTitle] of this.watched) {
      const known = this.ageOf(key);
      const stale = Boolean(known?.stale);
      if (element.classList.contains("stale") !== stale) element.classList.toggle("stale", stale);
      const text = known ? shownAge(known.ageS, stale) : "";
      if (element.dataset.age !== text) element.dataset.age = text;
      if (ownTitle) continue;
      const when = text === FRESH ? FRESH : `${text} ago`;
      const title = known ? `${(SOURCES[key] || [key]).join(" / ")}: ${when}` : "not received yet";
      if (element.title !== title) element.title = title;
    }
  }
}

// ---- drawing helpers ----------------------------------------------------------------------

function el(name, attrs = {}, parent = null) {
  const node = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  if (parent) parent.append(node);
  return node;
}

function text(parent, x, y, content, attrs = {}) {
  const node = el("text", { x, y, ...attrs }, parent);
  node.textContent = content;
  return node;
}

const setTextOf = (node, content) => { if (node.textContent !== content) node.textContent = content; };
const finite = (x) => typeof x === "number" && Number.isFinite(x);

// ---- attitude indicator -----------------------------------------------------------------

const PITCH_PX_PER_DEG = 2.2;
const ROLL_TICKS_DEG = [-60, -45, -30, -20, -10, 0, 10, 20, 30, 45, 60];

class AttitudeIndicator {
  constructor(container) {
    const svg = el("svg", { viewBox: "-100 -100 200 200", class: "adi", role: "img", "aria-label": "attitude indicator" }, container);
    const clip = el("clipPath", { id: "adi-clip" }, el("defs", {}, svg));
    el("circle", { r: 92 }, clip);
    const face = el("g", { "clip-path": "url(#adi-clip)" }, svg);
    this.horizon = el("g", { class: "adi-horizon" }, face);
    el("rect", { x: -400, y: -800, width: 800, height: 800, class: "adi-sky" }, this.horizon);
    el("rect", { x: -400, y: 0, width: 800, height: 800, class: "adi-ground" }, this.horizon);
    el("line", { x1: -400, y1: 0, x2: 400, y2: 0, class: "adi-horizon-line" }, this.horizon);
    for (let p = -90; p <= 90; p += 5) {
      if (p === 0) continue;
      const y = -p * PITCH_PX_PER_DEG;
      const half = p % 10 === 0 ? 22 : 10;
      el("line", { x1: -half, y1: y, x2: half, y2: y, class: "adi-ladder" }, this.horizon);
      if (p % 10 === 0) {
        text(this.horizon, -half - 4, y + 3, String(Math.abs(p)), { class: "adi-ladder-label", "text-anchor": "end" });
        text(this.horizon, half + 4, y + 3, String(Math.abs(p)), { class: "adi-ladder-label" });
      }
    }
    // roll scale (fixed) and its pointer (turns with the horizon)
    const scale = el("g", { class: "adi-roll-scale" }, svg);
    el("path", { d: "M -70.7 -70.7 A 100 100 0 0 1 70.7 -70.7", transform: "scale(0.86)" }, scale);
    for (const r of ROLL_TICKS_DEG) {
      const long = r % 30 === 0;
      el("line", { x1: 0, y1: -86, x2: 0, y2: long ? -96 : -92, transform: `rotate(${r})` }, scale);
    }
    this.rollPointer = el("path", { d: "M 0 -85 L -5 -76 L 5 -76 Z", class: "adi-roll-pointer" }, svg);
    el("path", { d: "M 0 -87 L -5 -96 L 5 -96 Z", class: "adi-roll-index" }, svg);
    // the aircraft symbol (fixed)
    const plane = el("g", { class: "adi-aircraft" }, svg);
    el("path", { d: "M -48 0 L -16 0 L -8 8 M 48 0 L 16 0 L 8 8" }, plane);
    el("circle", { r: 2.5 }, plane);
    el("circle", { r: 92, class: "adi-rim" }, svg);
    el("rect", { x: -34, y: 64, width: 68, height: 14, rx: 2, class: "adi-readout-box" }, svg);
    this.readout = text(svg, 0, 75, UNKNOWN, { class: "adi-readout", "text-anchor": "middle" });
  }

  show(attitude) {
    if (!attitude || !finite(attitude.roll_deg) || !finite(attitude.pitch_deg)) {
      setTextOf(this.readout, UNKNOWN);
      return;
    }
    const roll = attitude.roll_deg;
    const pitch = Math.max(-90, Math.min(90, attitude.pitch_deg));
    // to half a degree of roll (under a pixel at the rim) and half a pixel of pitch: a
    // hovering vehicle's jitter does not redraw the horizon ten times a second
    const r = Math.round(roll * 2) / 2;
    const p = Math.round(pitch * PITCH_PX_PER_DEG * 2) / 2;
    setAttr(this.horizon, "transform", `rotate(${-r}) translate(0 ${p})`);
    setAttr(this.rollPointer, "transform", `rotate(${-r})`);
    setTextOf(this.readout, `R ${num(roll, 0)}°  P ${num(pitch, 0)}°`);
  }
}

// ---- heading tape -------------------------------------------------------------------------

const TAPE_PX_PER_DEG = 2.4;
const CARDINALS = { 0: "N", 45: "NE", 90: "E", 135: "SE", 180: "S", 225: "SW", 270: "W", 315: "NW" };

class HeadingTape {
  constructor(container) {
    const svg = el("svg", { viewBox: "-130 0 260 36", class: "heading-tape", role: "img", "aria-label": "heading" }, container);
    const clip = el("clipPath", { id: "tape-clip" }, el("defs", {}, svg));
    el("rect", { x: -130, y: 0, width: 260, height: 36 }, clip);
    const window = el("g", { "clip-path": "url(#tape-clip)" }, svg);
    this.tape = el("g", { class: "tape-marks" }, window);
    for (let d = -180; d <= 540; d += 5) {
      const x = d * TAPE_PX_PER_DEG;
      const norm = ((d % 360) + 360) % 360;
      const major = norm % 15 === 0;
      el("line", { x1: x, y1: 0, x2: x, y2: major ? 10 : 5 }, this.tape);
      if (norm % 45 === 0) {
        text(this.tape, x, 20, CARDINALS[norm], { "text-anchor": "middle", class: "tape-cardinal" });
      } else if (norm % 15 === 0) {
        text(this.tape, x, 19, String(norm), { "text-anchor": "middle", class: "tape-label" });
      }
    }
    el("path", { d: "M 0 0 L -6 -1 L 0 9 L 6 -1 Z", class: "tape-index" }, svg);
    el("rect", { x: -22, y: 22, width: 44, height: 14, rx: 2, class: "tape-box" }, svg);
    this.readout = text(svg, 0, 33, UNKNOWN, { "text-anchor": "middle", class: "tape-readout" });
  }

  show(headingDeg) {
    if (!finite(headingDeg)) {
      setTextOf(this.readout, UNKNOWN);
      return;
    }
    const h = ((headingDeg % 360) + 360) % 360;
    setAttr(this.tape, "transform", `translate(${-Math.round(h * TAPE_PX_PER_DEG * 2) / 2} 0)`);
    setTextOf(this.readout, heading(h));
  }
}

// ---- battery time left ----------------------------------------------------------------------

const RATE_WINDOW_S = 60;
const RATE_MIN_SPAN_S = 15;

/** Time left on the battery: the vehicle's own figure, else from the current and the charge
 * used so far, else from how fast the remaining charge has been falling. */
export class BatteryClock {
  constructor() {
    this.samples = []; // [time_s, remaining_pct]
  }

  reset() {
    this.samples = [];
  }

  estimate(battery, nowS) {
    if (!battery) return null;
    if (finite(battery.time_remaining_s) && battery.time_remaining_s > 0) {
      return { seconds: battery.time_remaining_s, how: "vehicle" };
    }
    const pct = battery.remaining_pct;
    if (!finite(pct)) return null;
    const last = this.samples.at(-1);
    if (!last || last[1] !== pct || nowS - last[0] > 5) this.samples.push([nowS, pct]);
    while (this.samples.length > 2 && nowS - this.samples[0][0] > RATE_WINDOW_S) this.samples.shift();
    const used = 100 - pct;
    if (finite(battery.current_a) && battery.current_a > 0.1 && finite(battery.consumed_mah)
        && battery.consumed_mah > 0 && used >= 1) {
      const capacityMah = (battery.consumed_mah * 100) / used;
      const leftMah = (capacityMah * pct) / 100;
      return { seconds: (leftMah / (battery.current_a * 1000)) * 3600, how: "current" };
    }
    const first = this.samples[0];
    const spanS = nowS - first[0];
    const dropPct = first[1] - pct;
    if (spanS >= RATE_MIN_SPAN_S && dropPct > 0) return { seconds: (pct / dropPct) * spanS, how: "rate" };
    return null;
  }
}

// ---- the panel ------------------------------------------------------------------------------

const GOOD_FIXES = new Set(["3D_FIX", "DGPS", "RTK_FLOAT", "RTK_FIXED"]);
const ESTIMATOR_NEEDED = ["ATTITUDE", "VELOCITY_HORIZ", "POS_HORIZ_REL"];

// A div of the class (and id, when given) appended to the parent.
function panel(parent, className, id) {
  const box = document.createElement("div");
  box.className = className;
  if (id) box.id = id;
  parent.append(box);
  return box;
}

function tile(parent, id, label, source, freshness) {
  const box = document.createElement("div");
  box.className = "inst-tile";
  box.id = id;
  box.innerHTML = `<span class="inst-label">${label}</span><b class="inst-big">${UNKNOWN}</b><small class="inst-sub"></small>`;
  parent.append(box);
  freshness.watch(box, source);
  return { box, big: box.querySelector(".inst-big"), sub: box.querySelector(".inst-sub") };
}

function put(node, content) {
  if (node.textContent !== content) node.textContent = content;
}

function level(node, cls) {
  for (const c of ["good", "warn", "bad"]) {
    if (node.classList.contains(c) !== (c === cls)) node.classList.toggle(c, c === cls);
  }
}

export class Instruments {
  constructor(container, freshness = new Freshness()) {
    this.freshness = freshness;
    this.battery = new BatteryClock();
    container.classList.add("instruments");
    const tapeBox = panel(container, "inst-heading", "inst-heading");
    this.tape = new HeadingTape(tapeBox);
    freshness.watch(tapeBox, "heading");
    const adiBox = panel(container, "inst-adi", "inst-attitude");
    this.adi = new AttitudeIndicator(adiBox);
    freshness.watch(adiBox, "attitude");
    const grid = panel(container, "inst-grid");
    this.alt = tile(grid, "inst-alt", "Alt above home", "altitude", freshness);
    this.airspeed = tile(grid, "inst-airspeed", "Airspeed", "speed", freshness);
    this.vspeed = tile(grid, "inst-vspeed", "Vertical speed", "speed", freshness);
    this.batt = tile(grid, "inst-battery", "Battery", "battery", freshness);
    this.gps = tile(grid, "inst-gps", "GPS", "gps", freshness);
    this.ekf = tile(grid, "inst-ekf", "Estimator", "estimator", freshness);
    this.vtol = tile(grid, "inst-vtol", "VTOL", "landed", freshness);
    this.battBar = document.createElement("div");
    this.battBar.className = "inst-bar";
    this.battBar.append(document.createElement("i"));
    this.batt.box.append(this.battBar);
  }

  /** A new vehicle: forget what was learned of the last one's battery. */
  reset() {
    this.battery.reset();
  }

  /** Draws a state (its ages were taken by freshness.update() when it came). */
  show(state) {
    this.adi.show(state.attitude);
    this.tape.show(finite(state.heading_deg) ? state.heading_deg : state.attitude?.yaw_deg);
    const g = state.global;
    put(this.alt.big, withUnit(g?.alt_rel_m, "m"));
    put(this.alt.sub, g ? `AMSL ${withUnit(g.alt_amsl_m, "m")}` : "");
    const air = state.air_speed_m_s;
    put(this.airspeed.big, withUnit(air, "m/s"));
    put(this.airspeed.sub, `ground ${withUnit(state.ground_speed_m_s, "m/s")}`);
    const climb = state.climb_rate_m_s;
    const arrow = finite(climb) && Math.abs(climb) >= 0.05 ? (climb > 0 ? "↑ " : "↓ ") : "";
    put(this.vspeed.big, finite(climb) ? `${arrow}${signed(climb)} m/s` : UNKNOWN);
    put(this.vspeed.sub, "up is +");
    this.showBattery(state.battery);
    this.showGps(state.gps);
    this.showEstimator(state.estimator, state.sensors_unhealthy);
    this.showVtol(state);
  }

  showBattery(b) {
    const t = this.battery.estimate(b, performance.now() / 1000);
    const pct = b?.remaining_pct;
    put(this.batt.big, finite(pct) ? `${num(pct, 0)} %` : UNKNOWN);
    const parts = [];
    if (b) parts.push(`${withUnit(b.voltage_v, "V", 2)} · ${withUnit(b.current_a, "A")}`);
    if (t) parts.push(`${duration(t.seconds)} left${t.how === "vehicle" ? "" : " (est.)"}`);
    put(this.batt.sub, parts.join(" · "));
    const left = t ? String(Math.round(t.seconds)) : "";
    if (this.batt.box.dataset.timeLeftS !== left) this.batt.box.dataset.timeLeftS = left;
    level(this.batt.box, !finite(pct) ? "" : pct <= 15 ? "bad" : pct <= 30 ? "warn" : "good");
    setStyle(this.battBar.firstChild, "width", `${finite(pct) ? Math.max(0, Math.min(100, pct)) : 0}%`);
  }

  showGps(gps) {
    if (!gps) {
      put(this.gps.big, UNKNOWN);
      put(this.gps.sub, "");
      level(this.gps.box, "");
      return;
    }
    put(this.gps.big, words(gps.fix_type).replace("d fix", "D fix"));
    put(this.gps.sub, `${gps.satellites} sats · hdop ${num(gps.hdop, 1)}`);
    const good = GOOD_FIXES.has(gps.fix_type) && gps.satellites >= 6;
    level(this.gps.box, good ? "good" : gps.fix_type === "2D_FIX" ? "warn" : "bad");
  }

  showEstimator(ekf, sensors) {
    if (!ekf) {
      put(this.ekf.big, UNKNOWN);
      put(this.ekf.sub, sensors?.length ? `unhealthy: ${sensors.map(words).join(", ")}` : "");
      level(this.ekf.box, sensors?.length ? "bad" : "");
      return;
    }
    const missing = ESTIMATOR_NEEDED.filter((f) => !ekf.flags.includes(f));
    const problems = [...missing.map((f) => `no ${words(f)}`)];
    if (ekf.flags.includes("GPS_GLITCH")) problems.push("GPS glitch");
    if (ekf.flags.includes("ACCEL_ERROR")) problems.push("accel error");
    if (sensors?.length) problems.push(`unhealthy: ${sensors.map(words).join(", ")}`);
    put(this.ekf.big, ekf.healthy && !sensors?.length ? "OK" : "CHECK");
    put(this.ekf.sub, problems.length ? problems.join(" · ") : `pos test ${num(ekf.pos_horiz_ratio, 2)}`);
    level(this.ekf.box, ekf.healthy ? (sensors?.length ? "warn" : "good") : "bad");
  }

  showVtol(state) {
    const vs = state.vtol_state;
    const isVtol = /VTOL/.test(state.vehicle_type || "") || (vs && vs !== "UNDEFINED");
    if (this.vtol.box.classList.contains("hidden") === isVtol) this.vtol.box.classList.toggle("hidden", !isVtol);
    if (!isVtol) return;
    // in transition the tile says where to, as the VTOL panel does ("→ FW"), so it holds it whole
    const names = { MC: "Multicopter", FW: "Fixed wing", TRANSITION_TO_FW: "→ FW", TRANSITION_TO_MC: "→ MC" };
    put(this.vtol.big, names[vs] || UNKNOWN);
    put(this.vtol.sub, vs?.startsWith("TRANSITION") ? "transition" : words(state.landed_state || ""));
    level(this.vtol.box, vs?.startsWith("TRANSITION") ? "warn" : "good");
  }
}
