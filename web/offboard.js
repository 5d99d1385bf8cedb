// The offboard panel: setpoint types with a slider and a number per field, their API
// bodies, and keyboard velocity control.

// POSITION_TARGET_TYPEMASK bits (MAVLink): ignore x, y, vz, the accelerations and yaw rate,
// leaving velocity x/y with position z: velocity in the horizontal plane at a held altitude.
const IGNORE_PX = 1, IGNORE_PY = 2, IGNORE_VZ = 32, IGNORE_ACCEL = 64 | 128 | 256;
const IGNORE_YAW_RATE = 2048;
const ALT_HOLD_VELOCITY_MASK = IGNORE_PX | IGNORE_PY | IGNORE_VZ | IGNORE_ACCEL | IGNORE_YAW_RATE;
const MAV_FRAME_LOCAL_NED = 1;

const f = (key, label, unit, min, max, step, value = 0) => ({ key, label, unit, min, max, step, value });

export const SETPOINT_TYPES = {
  position: [
    f("north_m", "North", "m", -100, 100, 0.5), f("east_m", "East", "m", -100, 100, 0.5),
    f("alt_m", "Altitude", "m", 0, 60, 0.1, 5), f("yaw_deg", "Yaw", "deg", -180, 180, 1),
  ],
  velocity: [
    f("north_m_s", "North", "m/s", -5, 5, 0.1), f("east_m_s", "East", "m/s", -5, 5, 0.1),
    f("up_m_s", "Up", "m/s", -3, 3, 0.1), f("yaw_rate_deg_s", "Yaw rate", "deg/s", -90, 90, 1),
  ],
  velocity_body: [
    f("forward_m_s", "Forward", "m/s", -5, 5, 0.1), f("right_m_s", "Right", "m/s", -5, 5, 0.1),
    f("up_m_s", "Up", "m/s", -3, 3, 0.1), f("yaw_rate_deg_s", "Yaw rate", "deg/s", -90, 90, 1),
  ],
  alt_hold_velocity: [
    f("north_m_s", "North", "m/s", -5, 5, 0.1), f("east_m_s", "East", "m/s", -5, 5, 0.1),
    f("alt_m", "Altitude", "m", 0, 60, 0.1, 5), f("yaw_deg", "Yaw", "deg", -180, 180, 1),
  ],
  attitude: [
    f("roll_deg", "Roll", "deg", -30, 30, 0.5), f("pitch_deg", "Pitch", "deg", -30, 30, 0.5),
    f("yaw_deg", "Yaw", "deg", -180, 180, 1), f("thrust", "Thrust", "0..1", 0, 1, 0.01, 0.5),
  ],
};

/** The API setpoint body for a panel type and its values; altitudes are above home. */
export function setpointBody(type, v, homeDownM = 0) {
  const down = (altM) => homeDownM - altM;
  switch (type) {
    case "position":
      return { type: "position_ned", north_m: v.north_m, east_m: v.east_m, down_m: down(v.alt_m), yaw_deg: v.yaw_deg };
    case "velocity":
      return { type: "velocity_ned", north_m_s: v.north_m_s, east_m_s: v.east_m_s, down_m_s: -v.up_m_s, yaw_rate_deg_s: v.yaw_rate_deg_s };
    case "velocity_body":
      return { type: "velocity_body", forward_m_s: v.forward_m_s, right_m_s: v.right_m_s, down_m_s: -v.up_m_s, yaw_rate_deg_s: v.yaw_rate_deg_s };
    case "alt_hold_velocity":
      return {
        type: "raw_local", frame: MAV_FRAME_LOCAL_NED, type_mask: ALT_HOLD_VELOCITY_MASK,
        x: 0, y: 0, z: down(v.alt_m), vx: v.north_m_s, vy: v.east_m_s, vz: 0,
        yaw: (v.yaw_deg * Math.PI) / 180,
      };
    case "attitude":
      return { type: "attitude", roll_deg: v.roll_deg, pitch_deg: v.pitch_deg, yaw_deg: v.yaw_deg, thrust: v.thrust };
    default:
      throw new Error(`unknown setpoint type ${type}`);
  }
}

/** Panel values that hold the vehicle where it is (for "Here" and for switching types). */
export function valuesFromState(type, state) {
  const values = {};
  for (const field of SETPOINT_TYPES[type]) values[field.key] = field.value;
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

/** Builds the fields of the current type; calls onChange(values) as sliders move. */
export class SetpointPanel {
  constructor(container, onChange) {
    this.container = container;
    this.onChange = onChange;
    this.type = "position";
    this.values = {};
    this.inputs = {};
  }

  show(type, values) {
    this.type = type;
    this.values = { ...values };
    this.inputs = {};
    this.container.replaceChildren();
    for (const field of SETPOINT_TYPES[type]) {
      const row = document.createElement("div");
      row.className = "sp-field";
      const label = document.createElement("label");
      label.textContent = field.label;
      const slider = this.input("range", field, `sp-${field.key}-slider`);
      const number = this.input("number", field, `sp-${field.key}`);
      number.classList.add("num");
      const unit = document.createElement("span");
      unit.className = "unit";
      unit.textContent = field.unit;
      const sync = (source, other) => {
        const value = parseFloat(source.value);
        if (!Number.isFinite(value)) return;
        other.value = value;
        this.values[field.key] = value;
        this.onChange(this.values);
      };
      slider.addEventListener("input", () => sync(slider, number));
      number.addEventListener("input", () => sync(number, slider));
      this.inputs[field.key] = [slider, number];
      row.append(label, slider, number, unit);
      this.container.append(row);
    }
  }

  input(kind, field, id) {
    const el = document.createElement("input");
    el.type = kind;
    el.id = id;
    el.className = "ctl";
    el.min = field.min;
    el.max = field.max;
    el.step = field.step;
    el.value = this.values[field.key] ?? field.value;
    return el;
  }

  set(values) {
    Object.assign(this.values, values);
    for (const [key, value] of Object.entries(values)) {
      for (const el of this.inputs[key] || []) el.value = value;
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

/** Keyboard velocity control: body-frame velocity while keys are held, space = hold here. */
export class KeyboardPilot {
  constructor({ enabled, speed, onVelocity, onHold, onKeys }) {
    this.enabled = enabled;
    this.speed = speed;
    this.onVelocity = onVelocity;
    this.onHold = onHold;
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
      this.onKeys("HOLD");
      this.onHold();
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
    this.send();
    if (this.held.size === 0) this.stopTimer();
  }

  releaseAll() {
    if (this.held.size === 0) return;
    this.held.clear();
    this.send();
    this.stopTimer();
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
