// The offboard panel: a slider and a number per setpoint field, their API bodies, and
// keyboard velocity control. The setpoint kinds, their field names, units and limits are read
// from the API's /openapi.json (built from the link's one definition); this module only says
// which kind each panel type sends, how a field is shown, and the sliders' display ranges.

import { API_PREFIX, CALLS, VEHICLE_PATH } from "./calls.js";

// the PUT setpoint route as /openapi.json names it
const SETPOINT_PATH = `${API_PREFIX}${VEHICLE_PATH}/${CALLS.set_setpoint[1]}`;

// How a panel shows an API field: under another key and label, as api = scale·value (+ the
// home's down_m when fromHome: altitudes above home), in another unit.
const ALTITUDE = { key: "alt_m", label: "Altitude", scale: -1, fromHome: true };
const UP = { key: "up_m_s", label: "Up", scale: -1 };

// Panel types: the API kind whose fields each shows; `show` picks and orders them (default:
// all), `views` changes how one shows, `fixed` values are sent as they are. A panel with an
// `intent` sends that intent with its fields instead of a setpoint (the server decides how
// it is flown, e.g. the held altitude).
const PANELS = {
  position: { kind: "position_ned", views: { down_m: ALTITUDE } },
  velocity: {
    kind: "velocity_ned", show: ["north_m_s", "east_m_s", "down_m_s", "yaw_rate_deg_s"],
    views: { down_m_s: UP },
  },
  velocity_body: { kind: "velocity_body", views: { down_m_s: UP } },
  alt_hold_velocity: {
    kind: "velocity_ned", show: ["north_m_s", "east_m_s", "yaw_rate_deg_s"],
    intent: "velocity", fixed: { frame: "ned", hold_altitude: true, live: false },
  },
  attitude: { kind: "attitude" },
};

// The sliders' display ranges by panel key, else by unit: [min, max, step], or a window
// {span, step, min?, max?}: a slider `span` wide around the field's value, re-centred when the
// form takes its values from the vehicle or the setpoint flown, and when the value nears an end
// (so at 1280x800 a pixel is a fifth of a metre, not 2 m), inside min..max and the API's limits.
// The number beside a slider takes any value the API accepts; the first value of a field is 0
// unless INITIAL says otherwise.
const DISPLAY_BY_KEY = {
  alt_m: { span: 30, step: 0.1, min: 0 }, up_m_s: [-3, 3, 0.1], roll_deg: [-30, 30, 0.5],
  pitch_deg: [-30, 30, 0.5],
};
const DISPLAY_BY_UNIT = {
  m: { span: 50, step: 0.1 }, "m/s": [-5, 5, 0.1], "m/s^2": [-5, 5, 0.1], deg: [-180, 180, 1],
  "deg/s": [-90, 90, 1], 1: [0, 1, 0.01],
};
// A window re-centres when a value comes within this share of its span from an end.
const WINDOW_EDGE = 0.1;
const INITIAL = { alt_m: 5, thrust: 0.5 };

/** Panel type -> its fields ({key, label, unit, min, max, step, span, value, api, scale, fromHome}:
 * min..max a fixed slider range, or the bounds of a window `span` wide),
 * filled from the API schema by loadSetpointKinds(). */
export const SETPOINT_TYPES = {};

let kindsLoaded = null;

/** Reads the setpoint kinds from /openapi.json into SETPOINT_TYPES (once; again after a
 * failure). */
export function loadSetpointKinds() {
  kindsLoaded ??= fetch("/openapi.json")
    .then((answer) => answer.json())
    .then((schema) => {
      const kinds = setpointKinds(schema);
      for (const [type, panel] of Object.entries(PANELS)) SETPOINT_TYPES[type] = panelFields(panel, kinds);
    })
    .catch((err) => {
      kindsLoaded = null;
      throw err;
    });
  return kindsLoaded;
}

/** kind -> {field name -> {unit, min, max}} from the PUT setpoint body's discriminator. */
export function setpointKinds(schema) {
  const body = schema.paths[SETPOINT_PATH].put.requestBody.content["application/json"].schema;
  const kinds = {};
  for (const [kind, ref] of Object.entries(body.discriminator.mapping)) {
    const component = schema.components.schemas[ref.split("/").pop()];
    kinds[kind] = {};
    for (const [name, property] of Object.entries(component.properties)) {
      if (name === "type") continue;
      const number = (property.anyOf || [property]).find((branch) => branch.type !== "null");
      kinds[kind][name] = { unit: number["x-unit"], min: number.minimum, max: number.maximum };
    }
  }
  return kinds;
}

function panelFields(panel, kinds) {
  const fields = kinds[panel.kind];
  if (!fields) throw new Error(`the API has no setpoint kind ${panel.kind}`);
  return (panel.show || Object.keys(fields).filter((name) => !(name in (panel.fixed || {})))).map((api) => {
    if (!fields[api]) throw new Error(`setpoint kind ${panel.kind} has no field ${api}`);
    const view = { key: api, label: labelOf(api), scale: 1, ...panel.views?.[api] };
    const { unit, min, max } = fields[api];
    const limits = [min / view.scale, max / view.scale].sort((a, b) => a - b);
    const shownUnit = view.unit ?? unit;
    const display = DISPLAY_BY_KEY[view.key] ?? DISPLAY_BY_UNIT[shownUnit] ?? [...limits, 0.01];
    const [low, high, step] = Array.isArray(display)
      ? display : [display.min ?? -Infinity, display.max ?? Infinity, display.step];
    return {
      key: view.key, label: view.label, unit: shownUnit === "1" ? `${min}..${max}` : shownUnit,
      valid: limits, min: Math.max(low, limits[0]), max: Math.min(high, limits[1]), step,
      span: Array.isArray(display) ? null : display.span,
      value: INITIAL[view.key] ?? 0, api, scale: view.scale, fromHome: Boolean(view.fromHome),
    };
  });
}

/** "yaw_rate_deg_s" -> "Yaw rate": the name without its unit. */
function labelOf(name) {
  const words = name.replace(/(_(m|s|s2|deg|rad))+$/, "").split("_");
  const text = words.join(" ");
  return text.charAt(0).toUpperCase() + text.slice(1);
}

/** What a panel type sends for its values: `{setpoint}` (a setpoint body) or `{intent, args}`;
 * altitudes are above home. */
export function panelMessage(type, v, homeDownM = 0) {
  const panel = PANELS[type];
  if (!panel) throw new Error(`unknown setpoint type ${type}`);
  const fields = {};
  for (const field of SETPOINT_TYPES[type] || []) {
    fields[field.api] = field.scale * v[field.key] + (field.fromHome ? homeDownM : 0);
  }
  if (panel.intent) return { intent: panel.intent, args: { ...panel.fixed, ...fields } };
  return { setpoint: { type: panel.kind, ...panel.fixed, ...fields } };
}

/** The panel type and values that show a setpoint the vehicle flies (from the state or an
 * answer), or null for a kind no panel shows. */
export function panelForSetpoint(setpoint, homeDownM = 0) {
  if (!setpoint) return null;
  const entry = Object.entries(PANELS).find(([, panel]) => !panel.intent && panel.kind === setpoint.type);
  if (!entry) return null;
  const [type] = entry;
  const values = {};
  for (const field of SETPOINT_TYPES[type] || []) {
    const api = setpoint[field.api];
    if (!Number.isFinite(api)) continue;
    values[field.key] = round((api - (field.fromHome ? homeDownM : 0)) / field.scale, 2);
  }
  return { type, values };
}

const PANEL_LABELS = {
  position: "Position", velocity: "Velocity NED", velocity_body: "Velocity body", attitude: "Attitude",
};

/** The setpoint the vehicle flies, in the panel's own terms: "Position · North 10 m · East 0 m
 * · Altitude 5 m · Yaw 90 deg", or "–" when none is streamed. */
export function flownText(setpoint, homeDownM = 0) {
  const shown = panelForSetpoint(setpoint, homeDownM);
  if (!shown) return setpoint ? String(setpoint.type || "setpoint").replaceAll("_", " ") : "–";
  const parts = (SETPOINT_TYPES[shown.type] || [])
    .filter((field) => Number.isFinite(shown.values[field.key]))
    .map((field) => {
      const v = shown.values[field.key];
      const text = Math.abs(v) < 0.05 ? "0" : String(Math.round(v * 10) / 10);
      return `${field.label} ${text}${field.unit && !field.unit.includes("..") ? ` ${field.unit}` : ""}`;
    });
  return [PANEL_LABELS[shown.type] || shown.type, ...parts].join(" · ");
}

/** Panel values that hold the vehicle where it is (what the fields follow, and a new type's). */
export function valuesFromState(type, state) {
  const values = {};
  for (const field of SETPOINT_TYPES[type] || []) values[field.key] = field.value;
  const p = state && state.position_ned;
  const homeDown = state && state.home ? state.home.down_m : 0;
  const yaw = state && state.attitude ? state.attitude.yaw_deg : 0;
  if (p && "north_m" in values) {
    values.north_m = round(p.north_m, 1);
    values.east_m = round(p.east_m, 1);
  }
  if (p && "alt_m" in values) values.alt_m = round(Math.max(0, homeDown - p.down_m), 1);
  if ("yaw_deg" in values && Number.isFinite(yaw)) values.yaw_deg = Math.round(yaw);
  return values;
}

const round = (x, digits) => Math.round(x * 10 ** digits) / 10 ** digits;

/** A field's slider range [min, max] around a value: its fixed range, or its window centred on
 * the value (in whole units), moved inside the field's bounds. */
export function sliderRange(field, value) {
  if (!field.span) return [field.min, field.max];
  const centre = Number.isFinite(value) ? Math.round(value) : field.value;
  const low = Math.max(field.min, Math.min(centre - field.span / 2, field.max - field.span));
  return [low, Math.min(field.max, low + field.span)];
}

/** Whether a value lies outside a windowed field's slider range or near one of its ends (an
 * end the window can still move past). */
export function nearAnEnd(field, [min, max], value) {
  if (!field.span || !Number.isFinite(value)) return false;
  const edge = field.span * WINDOW_EDGE;
  return (value < min + edge && min > field.min) || (value > max - edge && max < field.max);
}

// The fields that follow the vehicle (where it is, or the setpoint it flies) until the pilot
// edits them.
const FOLLOWED = new Set(["north_m", "east_m", "alt_m", "yaw_deg"]);
// a move this small reads 0: the fields follow the vehicle to 0.1 m, and it wobbles a little
const MOVE_DEAD_BAND_M = 0.3;
const fmtSigned = (x, dead = MOVE_DEAD_BAND_M) => (Math.abs(x) < dead ? "0"
  : `${x > 0 ? "+" : "−"}${Math.round(Math.abs(x) * 10) / 10}`);

/** The move a position panel's values ask for, from where the vehicle is now: "north +10 m,
 * east 0 m, up 0 m" (and the yaw when it turns), or "" when it cannot be told. */
export function moveText(type, values, state) {
  if (type !== "position" || !state?.position_ned) return "";
  const p = state.position_ned;
  const homeDown = state.home ? state.home.down_m : NaN;
  const parts = [
    `north ${fmtSigned(values.north_m - p.north_m)} m`, `east ${fmtSigned(values.east_m - p.east_m)} m`,
  ];
  if (Number.isFinite(homeDown)) parts.push(`up ${fmtSigned(values.alt_m - (homeDown - p.down_m))} m`);
  const yaw = state.attitude?.yaw_deg;
  if (Number.isFinite(yaw) && Number.isFinite(values.yaw_deg)) {
    const turn = ((values.yaw_deg - yaw + 540) % 360) - 180;
    if (Math.abs(turn) >= 1) parts.push(`yaw ${fmtSigned(turn, 0.5)}°`);
  }
  return parts.join(", ");
}

/** Builds the fields of the current type; calls onChange(values) as sliders move, and
 * onCommit() when an edit is done (a number's Enter or leaving it, a slider let go). The
 * fields of FOLLOWED follow the vehicle (follow()) until the pilot edits one: each says
 * "following" or "edited", and followAgain() takes the edits back. */
export class SetpointPanel {
  constructor(container, onChange, onCommit = () => {}) {
    this.container = container;
    this.onChange = onChange;
    this.onCommit = onCommit;
    this.type = "position";
    this.values = {};
    this.inputs = {};
    this.fields = {};
    this.tags = {};
    this.edited = new Set();
    this.loaded = false;
    this.loading = null;
    this.load();
  }

  /** Reads the kinds (unless already under way), then shows the current type. */
  load() {
    this.loading ??= loadSetpointKinds().then(() => {
      this.loaded = true;
      this.show(this.type, this.values);
    }, (err) => {
      this.container.textContent = `setpoint kinds not read from /openapi.json: ${err.message}`;
    }).finally(() => {
      this.loading = null;
    });
  }

  /** Shows a panel type's fields; until the kinds are read, the type and values wait. */
  show(type, values) {
    this.type = type;
    this.values = { ...values };
    this.inputs = {};
    this.fields = {};
    this.tags = {};
    this.edited.clear();
    this.container.replaceChildren();
    if (!this.loaded) {
      this.load();
      return;
    }
    for (const field of SETPOINT_TYPES[type]) {
      this.values[field.key] ??= field.value;
      const row = document.createElement("div");
      row.className = "sp-field";
      const label = document.createElement("label");
      label.textContent = field.label;
      if (FOLLOWED.has(field.key)) {
        const tag = document.createElement("small");
        tag.className = "sp-tag";
        tag.id = `sp-${field.key}-tag`;
        label.append(" ", tag);
        this.tags[field.key] = tag;
      }
      const slider = this.input(
        "range", field, `sp-${field.key}-slider`, sliderRange(field, this.values[field.key]),
      );
      const number = this.input("number", field, `sp-${field.key}`, field.valid);
      number.classList.add("num");
      label.htmlFor = number.id;
      const unit = document.createElement("span");
      unit.className = "unit";
      unit.textContent = field.unit;
      const sync = (source, other) => {
        const value = parseFloat(source.value);
        if (!Number.isFinite(value)) return;
        other.value = value;
        this.values[field.key] = value;
        this.markEdited(field.key, true);
        this.onChange(this.values);
      };
      // Re-centred once a drag ends (moving the range under a held thumb would make it jump),
      // or at once for a typed value.
      slider.addEventListener("input", () => sync(slider, number));
      slider.addEventListener("change", () => {
        this.recentre(field, false);
        this.onCommit(field.key);
      });
      number.addEventListener("input", () => {
        this.recentre(field, false);
        sync(number, slider);
      });
      number.addEventListener("change", () => this.onCommit(field.key));
      this.fields[field.key] = field;
      this.inputs[field.key] = [slider, number];
      row.append(label, slider, number, unit);
      this.container.append(row);
      this.markEdited(field.key, false);
    }
  }

  /** A field edited by the pilot (it stops following the vehicle), or following again. */
  markEdited(key, edited) {
    if (edited) this.edited.add(key);
    else this.edited.delete(key);
    const tag = this.tags[key];
    if (!tag) return;
    const text = edited ? "edited" : "following";
    if (tag.textContent !== text) {
      tag.textContent = text;
      tag.classList.toggle("edited", edited);
      tag.title = edited
        ? "you set this value: it no longer follows the vehicle (Follow takes it back)"
        : "follows the vehicle (where it is, or the setpoint it flies) until you edit it";
    }
  }

  /** Whether any followed field was edited. */
  anyEdited() {
    return [...this.edited].some((key) => FOLLOWED.has(key));
  }

  /** The values of the vehicle for the fields the pilot has not edited. */
  follow(values) {
    const changed = {};
    for (const [key, value] of Object.entries(values)) {
      if (this.edited.has(key) || !(key in this.inputs) || !Number.isFinite(value)) continue;
      if (Math.abs((this.values[key] ?? NaN) - value) >= 0.05 || !Number.isFinite(this.values[key])) changed[key] = value;
    }
    if (Object.keys(changed).length) this.set(changed);
  }

  /** Every field (or those of `keys`) follows the vehicle again. */
  followAgain(keys = [...this.edited]) {
    for (const key of keys) this.markEdited(key, false);
  }

  input(kind, field, id, range) {
    const el = document.createElement("input");
    el.type = kind;
    el.id = id;
    el.className = "ctl";
    el.step = field.step;
    if (kind === "range") this.setRange(el, field, range);
    else [el.min, el.max] = range;
    el.value = this.values[field.key];
    return el;
  }

  /** A slider's range, and its title saying what the ends are. */
  setRange(slider, field, [min, max]) {
    slider.min = min;
    slider.max = max;
    const unit = field.unit.includes("..") ? "" : ` ${field.unit}`;
    slider.title = field.span
      ? `${min} to ${max}${unit} (moves with the value; type any value in the box)`
      : `${min} to ${max}${unit}`;
  }

  /** Centres a windowed field's slider on the field's value: always, or only when the value
   * is out of the window or near one of its ends. */
  recentre(field, always) {
    const [slider, number] = this.inputs[field.key] || [];
    if (!slider || !field.span) return;
    const typed = parseFloat(number.value);
    const value = Number.isFinite(typed) ? typed : this.values[field.key];
    if (!always && !nearAnEnd(field, [parseFloat(slider.min), parseFloat(slider.max)], value)) return;
    this.setRange(slider, field, sliderRange(field, value));
    slider.value = value;
  }

  /** Takes values from the vehicle or the setpoint it flies (the fields follow it again);
   * the windows centre on them. */
  set(values) {
    const before = { ...this.values };
    Object.assign(this.values, values);
    for (const [key, value] of Object.entries(values)) {
      const [slider, number] = this.inputs[key] || [];
      if (!slider) continue;
      // shown already (the setpoint flown, given again with every state): no DOM write, so
      // an observer's page redraws nothing while the vehicle flies the same setpoint
      if (before[key] === value && !this.edited.has(key) && number.value === String(value)) continue;
      this.markEdited(key, false);
      number.value = value;
      this.recentre(this.fields[key], true);
      slider.value = value;
    }
  }
}

const KEYS = {
  KeyW: ["forward", 1], ArrowUp: ["forward", 1], KeyS: ["forward", -1], ArrowDown: ["forward", -1],
  KeyD: ["right", 1], ArrowRight: ["right", 1], KeyA: ["right", -1], ArrowLeft: ["right", -1],
  KeyR: ["up", 1], KeyF: ["up", -1], KeyE: ["yaw", 1], KeyQ: ["yaw", -1],
};
const YAW_RATE_DEG_S = 45;
const MAX_CLIMB_M_S = 1.5;

/** Keyboard velocity control: body-frame velocity while keys are held (repeated, so the
 * server's deadman sees a live input), a brake when the last key is let go, space = brake. */
export class KeyboardPilot {
  constructor({ enabled, speed, onVelocity, onBrake, onKeys }) {
    this.enabled = enabled;
    this.speed = speed;
    this.onVelocity = onVelocity;
    this.onBrake = onBrake;
    this.onKeys = onKeys;
    this.held = new Set();
    this.timer = null;
    window.addEventListener("keydown", (e) => this.down(e));
    window.addEventListener("keyup", (e) => this.up(e));
    window.addEventListener("blur", () => this.releaseAll());
  }

  static typing(event) {
    const tag = event.target && event.target.tagName;
    return (tag === "INPUT" && event.target.type !== "range" && event.target.type !== "checkbox")
      || tag === "SELECT" || tag === "TEXTAREA";
  }

  down(event) {
    if (!this.enabled() || KeyboardPilot.typing(event)) return;
    if (event.code === "Space") {
      // Space must never also press whichever button has the focus.
      event.preventDefault();
      document.activeElement?.blur();
      this.held.clear();
      this.stopTimer();
      this.onKeys("BRAKE");
      this.onBrake();
      return;
    }
    if (!(event.code in KEYS)) return;
    event.preventDefault();
    if (this.held.has(event.code)) return;
    this.held.add(event.code);
    this.send();
    if (!this.timer) this.timer = setInterval(() => this.send(), 100);
  }

  up(event) {
    if (event.code === "Space" && this.enabled() && !KeyboardPilot.typing(event)) event.preventDefault();
    if (!this.held.delete(event.code)) return;
    event.preventDefault();
    if (this.held.size === 0) this.releaseAll();
    else this.send();
  }

  /** Stops at once, without a brake: control was lost or given away. */
  stop() {
    this.held.clear();
    this.stopTimer();
    this.onKeys("–");
  }

  releaseAll() {
    if (this.held.size === 0 && !this.timer) return;
    this.stop();
    if (this.enabled()) this.onBrake();
  }

  stopTimer() {
    clearInterval(this.timer);
    this.timer = null;
  }

  velocity() {
    const v = { forward: 0, right: 0, up: 0, yaw: 0 };
    for (const code of this.held) {
      const [axis, sign] = KEYS[code];
      v[axis] += sign;
    }
    const speed = this.speed();
    return {
      forward_m_s: v.forward * speed, right_m_s: v.right * speed,
      up_m_s: v.up * Math.min(speed, MAX_CLIMB_M_S), yaw_rate_deg_s: v.yaw * YAW_RATE_DEG_S,
    };
  }

  send() {
    const v = this.velocity();
    this.onKeys(this.held.size ? [...this.held].join(" ") : "–");
    this.onVelocity(v);
  }
}
