// One rule for every way a pilot sends the vehicle somewhere (the offboard panel, the map
// click, go to lat/lon, go by an offset): a target that would take an airborne vehicle below
// a safe height above home, or change its altitude by more than a few metres, is asked about
// once, with the numbers, before it is sent.

const AIRBORNE = new Set(["IN_AIR", "TAKEOFF", "LANDING"]);
/** Below this height above home an airborne vehicle is close to the ground. */
export const SAFE_HEIGHT_M = 2;
/** A change of altitude larger than this is asked about. */
export const ALTITUDE_STEP_M = 3;
// a target this close to one already confirmed is not asked about again
const SAME_TARGET_M = 0.5;

const fmt = (x) => String(Math.round(x * 10) / 10);

export function airborne(state) {
  return Boolean(state?.armed) && AIRBORNE.has(state?.landed_state);
}

/** The vehicle's height above home now, or NaN. */
export function altitudeAboveHomeM(state) {
  const p = state?.position_ned;
  if (p && state?.home && Number.isFinite(state.home.down_m)) return state.home.down_m - p.down_m;
  const rel = state?.global?.alt_rel_m;
  return Number.isFinite(rel) ? rel : NaN;
}

/** The question to ask before flying an airborne vehicle to `targetM` above home, or null:
 * {title, text, confirm}. */
export function altitudeQuestion(state, targetM) {
  if (!airborne(state) || !Number.isFinite(targetM)) return null;
  const nowM = altitudeAboveHomeM(state);
  if (!Number.isFinite(nowM)) return null;
  const change = targetM - nowM;
  const low = targetM < SAFE_HEIGHT_M && change < -SAME_TARGET_M;
  if (!low && Math.abs(change) <= ALTITUDE_STEP_M) return null;
  const way = change < 0 ? "down" : "up";
  const why = low
    ? `below the safe ${SAFE_HEIGHT_M} m above home`
    : `more than ${ALTITUDE_STEP_M} m ${way} at once`;
  return {
    title: `${change < 0 ? "Descend" : "Climb"} to ${fmt(targetM)} m above home?`,
    text: `The vehicle is at ${fmt(nowM)} m above home. This takes it to ${fmt(targetM)} m `
      + `(${way} ${fmt(Math.abs(change))} m), ${why}.`,
    confirm: `${change < 0 ? "Descend" : "Climb"} to ${fmt(targetM)} m`,
  };
}

/** Asks at most once per target: a target the pilot confirmed is not asked about again. */
export class AltitudeGuard {
  constructor(ask) {
    this.ask = ask; // ({title, text, confirm}) => Promise<boolean>
    this.confirmedM = null;
    this.asking = null;
  }

  /** The question for a target, unless it was confirmed already. */
  question(state, targetM) {
    const question = altitudeQuestion(state, targetM);
    if (!question) return null;
    if (this.confirmedM !== null && Math.abs(targetM - this.confirmedM) < SAME_TARGET_M) return null;
    return question;
  }

  /** Resolves true when the target may be flown: nothing to ask, or the pilot confirmed. */
  async allows(state, targetM) {
    const question = this.question(state, targetM);
    if (!question) return true;
    if (this.asking) return this.asking;
    this.asking = this.ask(question).then((ok) => {
      if (ok) this.confirmedM = targetM;
      return ok;
    }).finally(() => { this.asking = null; });
    return this.asking;
  }

  forget() {
    this.confirmedM = null;
  }
}
