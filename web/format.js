// Numbers for people: never "-0.0", a unit after every value, ages and durations in s / min / h,
// "–" for what is not known.

export const UNKNOWN = "–";

/** x with `digits` decimals; a value that rounds to zero loses its sign ("0.0", not "-0.0"). */
export function num(x, digits = 1) {
  if (typeof x !== "number" || !Number.isFinite(x)) return UNKNOWN;
  const text = x.toFixed(digits);
  return /^-0\.?0*$/.test(text) ? text.slice(1) : text;
}

/** "12.5 m", "–" when unknown (then without the unit: "– m" reads as a value). */
export function withUnit(x, unit, digits = 1) {
  const text = num(x, digits);
  return text === UNKNOWN ? UNKNOWN : `${text} ${unit}`;
}

/** A signed value: "+1.2", "-0.4", "0.0". */
export function signed(x, digits = 1) {
  const text = num(x, digits);
  if (text === UNKNOWN || text.startsWith("-") || Number(text) === 0) return text;
  return `+${text}`;
}

/** An age in seconds: "0.4 s", "12 s", "3 min 05 s", "2 h 04 min". */
export function age(seconds) {
  if (typeof seconds !== "number" || !Number.isFinite(seconds)) return UNKNOWN;
  const s = Math.max(0, seconds);
  if (s < 10) return `${num(s, 1)} s`;
  if (s < 60) return `${Math.floor(s)} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${String(Math.floor(s % 60)).padStart(2, "0")} s`;
  return `${Math.floor(s / 3600)} h ${String(Math.floor((s % 3600) / 60)).padStart(2, "0")} min`;
}

/** A duration ahead, to the minute once it is long: "45 s", "12 min", "1 h 05 min". */
export function duration(seconds) {
  if (typeof seconds !== "number" || !Number.isFinite(seconds) || seconds < 0) return UNKNOWN;
  if (seconds < 60) return `${Math.round(seconds)} s`;
  // rounded to the minute first, so 9 h 59 min 50 s reads "10 h 00 min", never "9 h 60 min"
  const minutes = Math.round(seconds / 60);
  if (minutes < 60) return `${minutes} min`;
  return `${Math.floor(minutes / 60)} h ${String(minutes % 60).padStart(2, "0")} min`;
}

/** Milliseconds, as an age when long ("Since last 2 min 34 s", never "154753 ms"). */
export function millis(ms) {
  if (typeof ms !== "number" || !Number.isFinite(ms)) return UNKNOWN;
  return ms < 1000 ? `${Math.round(ms)} ms` : age(ms / 1000);
}

/** A heading as 0..359 ("000°" style is for tapes; here "7°", "359°"). */
export function heading(deg) {
  if (typeof deg !== "number" || !Number.isFinite(deg)) return UNKNOWN;
  return `${Math.round(((deg % 360) + 360) % 360) % 360}°`;
}

/** A bitmask flag name as words: "POS_HORIZ_ABS" → "pos horiz abs". */
export function words(name) {
  return String(name).toLowerCase().replaceAll("_", " ");
}

/** A deadman event in words: "deadman: brake (the pilot's live input fell silent for 0.5 s)
 * — position north 10.0 m east 2.0 m down -5.0 m", not its JSON. `vehicleSilentS`: how long
 * nothing has come from the vehicle; when that is the longer silence, the vehicle went silent
 * (the server refuses live input for a vehicle it does not hear), not the pilot. */
export function deadmanText(data, { vehicleSilentS = null, vehicle = "" } = {}) {
  const timeoutS = data.timeout_s;
  // a talking vehicle's freshest message is a few tens of ms old (and a state period more)
  const vehicleSilent = Number.isFinite(vehicleSilentS) && Number.isFinite(timeoutS)
    && vehicleSilentS >= Math.max(0.3, timeoutS / 2);
  const cause = data.cause !== "live_timeout" ? `operator ${words(data.cause || "lost")}`
    : vehicleSilent ? `${`vehicle ${vehicle}`.trim()} went silent ${age(vehicleSilentS)} ago: the pilot's input could not reach it`
      : `the pilot's live input fell silent for ${num(timeoutS, 1)} s`;
  const sp = data.setpoint;
  let what = "";
  if (sp && typeof sp === "object") {
    const parts = Object.entries(sp)
      .filter(([k, v]) => k !== "type" && typeof v === "number" && Number.isFinite(v))
      .map(([k, v]) => `${words(k.replace(/_(m|m_s|deg|deg_s)$/, ""))} ${num(v, 1)}`);
    what = ` — ${words(sp.type || "setpoint")} ${parts.join(" ")}`.trimEnd();
  }
  const outcome = data.ok === false ? ` — failed: ${data.reason || data.result || "no answer"}`
    : data.result ? ` — ${data.result}` : "";
  return `deadman: ${words(data.action || "action")} (${cause})${what}${outcome}`;
}
