// The page's shared state: which vehicle is shown, the sockets, the latest state. One object
// every module reads and writes, also exposed as window.skyhelm.page for the browser tests.

import { FLEET_VEHICLE_PATH, VEHICLE_PATH } from "./calls.js";
import { Freshness } from "./instruments.js";
import { Plots } from "./plots.js";

const $ = (id) => document.getElementById(id);

export const page = {
  vehicles: [],
  vehicleId: null,
  vehicleType: "",
  telemetry: null,
  control: null,
  wantControl: false,
  connected: false,
  state: null,
  vtol: { state: null, since: 0 },
  readOnly: false, // a replayed recording: nobody may take control
  rejected: false, // the server refused the token: the page stops asking
  sceneServed: undefined, // GET /config said whether the server serves the 3D scene
  // a fleet server (--fleet): the selected vehicle may be another edge's, {key, edge, id};
  // then vehicleId is its key ("edge/id") and every call goes through the fleet's routes
  fleetVehicle: null,
};

/** The REST path of the selected vehicle: its own, or the fleet server's proxy to its edge. */
export function vehiclePath(suffix = "") {
  const v = page.fleetVehicle;
  if (v) {
    return FLEET_VEHICLE_PATH.replace("{edge}", encodeURIComponent(v.edge))
      .replace("{vehicle_id}", encodeURIComponent(v.id)) + suffix;
  }
  return VEHICLE_PATH.replace("{vehicle_id}", encodeURIComponent(page.vehicleId)) + suffix;
}

// Any telemetry field can be picked; these two (with their setpoints) are computed by render.js.
export const plots = new Plots($("plots"), {
  derived: {
    alt_above_home_m: { label: "Altitude above home (m)", unit: "m" },
    ground_speed_m_s: { label: "Ground speed (m/s)", unit: "m/s" },
  },
  fields: ["alt_above_home_m", "ground_speed_m_s"],
});

// How old each value is (from the state's message ages); instruments and tables grey out by it.
export const freshness = new Freshness();
