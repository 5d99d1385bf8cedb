// The page's shared state: which vehicle is shown, the sockets, the latest state. One object
// every module reads and writes, also exposed as window.skyhelm.page for the browser tests.

import { StripChart } from "./plots.js";

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
};

export const plots = {
  alt: new StripChart($("plot-alt"), { unit: "m", minSpan: 2 }),
  speed: new StripChart($("plot-speed"), { unit: "m/s", minSpan: 1 }),
};
