// The mode menu: the PX4 modes a vehicle of this type has (a rover has no TAKEOFF, only a
// VTOL has VTOL_TAKEOFF), kept on the mode the vehicle flies unless the pilot is choosing.

import { $ } from "./ui.js";

const MULTICOPTER = [
  "MANUAL", "STABILIZED", "ACRO", "ALTCTL", "POSCTL", "POSCTL_ORBIT", "OFFBOARD", "HOLD",
  "TAKEOFF", "LAND", "RTL", "MISSION", "FOLLOW_TARGET", "PRECLAND",
];
const FIXED_WING = [
  "MANUAL", "STABILIZED", "ACRO", "ALTCTL", "POSCTL", "OFFBOARD", "HOLD", "TAKEOFF", "LAND",
  "RTL", "MISSION",
];
const VTOL = [...MULTICOPTER, "VTOL_TAKEOFF"];
const ROVER = ["MANUAL", "STABILIZED", "ACRO", "POSCTL", "OFFBOARD", "HOLD", "RTL", "MISSION"];
const MISSION_NOTE = "needs a mission uploaded by another tool (SkyHelm plans none)";
// How long the menu leaves the pilot's choice alone before following the vehicle again.
const CHOOSING_MS = 8000;

/** The vehicle class of a MAV_TYPE name as the state gives it ("QUADROTOR", "VTOL_…"). */
export function vehicleClass(vehicleType) {
  const type = (vehicleType || "").toUpperCase();
  if (type.startsWith("VTOL")) return "vtol";
  if (type === "FIXED_WING" || type === "FLAPPING_WING" || type === "AIRSHIP") return "plane";
  if (type === "GROUND_ROVER" || type === "SURFACE_BOAT") return "rover";
  return "multicopter";
}

const BY_CLASS = { multicopter: MULTICOPTER, plane: FIXED_WING, vtol: VTOL, rover: ROVER };

/** The modes to offer for a vehicle type, limited to the names the API accepts. */
export function modesFor(vehicleType, apiModes = null) {
  const modes = BY_CLASS[vehicleClass(vehicleType)];
  return apiModes ? modes.filter((mode) => apiModes.includes(mode)) : [...modes];
}

export class ModeMenu {
  constructor(select) {
    this.select = select;
    this.apiModes = null;
    this.type = null;
    this.choseAt = -Infinity;
    select.addEventListener("change", () => { this.choseAt = performance.now(); });
  }

  /** Reads the mode names the API accepts from its schema (once). */
  async load() {
    try {
      const schema = await (await fetch("/openapi.json")).json();
      const names = schema.components?.schemas?.ModeBody?.properties?.mode?.enum;
      if (Array.isArray(names) && names.length) this.apiModes = names;
    } catch {
      // the built-in lists are PX4's names
    }
    this.type = null;
  }

  /** Follows a state: the type's modes, and the mode flown unless the pilot is choosing. */
  follow(vehicleType, mode) {
    if (vehicleType !== this.type) {
      this.type = vehicleType;
      const option = (m) => {
        const el = document.createElement("option");
        el.value = el.textContent = m;
        return el;
      };
      const modes = modesFor(vehicleType, this.apiModes);
      // MISSION flies a mission uploaded by another tool: said so where it is offered
      const mission = modes.filter((m) => m === "MISSION");
      const group = document.createElement("optgroup");
      group.label = MISSION_NOTE;
      group.append(...mission.map(option));
      this.select.replaceChildren(...modes.filter((m) => m !== "MISSION").map(option),
        ...(mission.length ? [group] : []));
      this.choseAt = -Infinity;
    }
    const choosing = document.activeElement === this.select || performance.now() - this.choseAt < CHOOSING_MS;
    if (!mode || choosing || this.select.value === mode) return;
    if (![...this.select.options].some((o) => o.value === mode)) return;
    this.select.value = mode;
  }
}

export const modeMenu = new ModeMenu($("mode-select"));
