// The 2D map (Leaflet, vendored): every vehicle of the server with its heading, its trail
// of the last 60 s, home, and the setpoint or PX4's target it flies to; a click offers to
// fly the selected vehicle there (the server's goto intent, the same as the Reposition
// panel). Offline it draws a metre grid around home with a scale bar and a north arrow; with
// the server's map_tile_url (GET /config) it shows those tiles instead.

import { TelemetrySocket, callApi } from "./api.js";
import { altitudeAllowed, runCommand } from "./control.js";
import { Painter, boxShown, setAttr, setStyle } from "./draw.js";
import { inControl } from "./handover.js";
import { page } from "./page.js";
import { $, num } from "./ui.js";

const L = window.L;
const WGS84 = window.geodesic.Geodesic.WGS84;
const TRAIL_S = 60;
const TRAIL_MIN_STEP_M = 0.3;
// The others' states, for a server with several vehicles (the selected one comes on the
// page's own socket).
const OTHERS_RATE_HZ = 4;
const GRID_STEPS_M = [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000];
const GRID_MAX_LINES = 14;
const FIRST_ZOOM = 18;
const MAX_ZOOM = 22;
const TILE_MAX_NATIVE_ZOOM = 19;
const DEG = 180 / Math.PI;

// ---- geodesy (WGS-84 geodesics, GeographicLib) ---------------------------------------------

/** [lat, lon] of the point north_m / east_m from ref [lat, lon]. */
export function offsetLatLon(ref, northM, eastM) {
  const distance = Math.hypot(northM, eastM);
  if (distance === 0) return [ref[0], ref[1]];
  const r = WGS84.Direct(ref[0], ref[1], Math.atan2(eastM, northM) * DEG, distance);
  return [r.lat2, r.lon2];
}

/** { north_m, east_m } of point [lat, lon] seen from ref [lat, lon]. */
export function offsetOf(ref, point) {
  const r = WGS84.Inverse(ref[0], ref[1], point[0], point[1]);
  return { north_m: r.s12 * Math.cos(r.azi1 / DEG), east_m: r.s12 * Math.sin(r.azi1 / DEG) };
}

const finite = (...xs) => xs.every(Number.isFinite);
/** Two [lat, lon] (or null) the same: a layer is moved only when its point changed. */
const samePoint = (a, b) => a === b || Boolean(a && b && a[0] === b[0] && a[1] === b[1]);

/** [lat, lon] of the vehicle's local NED origin: reported, or worked back from home. */
function nedOrigin(state) {
  const o = state.origin;
  if (o && finite(o.lat_deg, o.lon_deg)) return [o.lat_deg, o.lon_deg];
  const h = state.home;
  if (h && finite(h.lat_deg, h.lon_deg, h.north_m, h.east_m)) {
    return offsetLatLon([h.lat_deg, h.lon_deg], -h.north_m, -h.east_m);
  }
  return null;
}

function vehicleLatLon(state) {
  const g = state.global;
  return g && finite(g.lat_deg, g.lon_deg) ? [g.lat_deg, g.lon_deg] : null;
}

function homeLatLon(state) {
  const h = state.home;
  return h && finite(h.lat_deg, h.lon_deg) ? [h.lat_deg, h.lon_deg] : null;
}

/** Where the vehicle is sent: the streamed position setpoint, else PX4's own target. */
function aimOf(state) {
  const sp = state.setpoint;
  if (state.stream?.active && sp && finite(sp.north_m, sp.east_m)) {
    return { kind: "setpoint", north_m: sp.north_m, east_m: sp.east_m };
  }
  const t = state.target_ned;
  if (t && finite(t.north_m, t.east_m) && state.mode !== "OFFBOARD") {
    return { kind: "target", north_m: t.north_m, east_m: t.east_m };
  }
  return null;
}

/** The same colour policy as the 3D scene: failsafe, offboard, armed, disarmed. */
function category(state) {
  if (!state.armed) return "disarmed";
  if (state.user_mode && state.user_mode !== state.mode) return "failsafe";
  return state.mode === "OFFBOARD" ? "offboard" : "armed";
}

// ---- one vehicle on the map ----------------------------------------------------------------

const ARROW_SVG = '<svg viewBox="-12 -12 24 24" aria-hidden="true"><path d="M0,-11 L7.5,9 L0,4.5 L-7.5,9 Z"/></svg>';

class VehicleLayer {
  constructor(map, id, onSelect) {
    this.id = id;
    this.trail = [];
    this.marker = L.marker([0, 0], {
      icon: L.divIcon({
        className: "map-vehicle", iconSize: [28, 28], iconAnchor: [14, 14],
        html: `${ARROW_SVG}<span class="map-vehicle-id">${id}</span>`,
      }),
      keyboard: false, title: `vehicle ${id}`, zIndexOffset: 1000,
    }).on("click", () => onSelect(id));
    this.trailLine = L.polyline([], { className: "map-trail", interactive: false });
    this.home = L.marker([0, 0], {
      icon: L.divIcon({ className: "map-home", iconSize: [18, 18], iconAnchor: [9, 9], html: "H" }),
      interactive: false, keyboard: false,
    });
    this.aimLine = L.polyline([], { className: "map-aim-line", interactive: false });
    this.aim = L.circleMarker([0, 0], { radius: 6, className: "map-aim", interactive: false });
    this.group = L.layerGroup([this.trailLine, this.aimLine]).addTo(map);
    this.map = map;
    this.shown = new Set();
    this.latLon = null;
  }

  show(layer, on) {
    if (on && !this.shown.has(layer)) { this.group.addLayer(layer); this.shown.add(layer); }
    if (!on && this.shown.has(layer)) { this.group.removeLayer(layer); this.shown.delete(layer); }
  }

  update(state, selected, nowS) {
    const here = vehicleLatLon(state);
    const heading = Number.isFinite(state.heading_deg) ? state.heading_deg : state.attitude?.yaw_deg;
    // what the layer shows from this state: the same as drawn (and no trail point to age
    // out) is nothing to do
    const px = (point) => (point ? this.map.latLngToLayerPoint(point).round() : null);
    const aimed = aimOf(state);
    // to the pixel: the map moves nothing by less (the trail keeps a point per pixel moved)
    const shown = JSON.stringify([px(here), Math.round(heading), category(state), selected,
      state.connected, px(homeLatLon(state)), aimed && [aimed.kind, Math.round(aimed.north_m * 10),
        Math.round(aimed.east_m * 10)], nedOrigin(state), this.map.getZoom()]);
    const trailAged = this.trail.length > 0 && nowS - this.trail[0][2] > TRAIL_S;
    if (shown === this.drawnAs && !trailAged) return;
    this.drawnAs = shown;
    this.latLon = here;
    this.show(this.marker, Boolean(here));
    if (here) {
      if (!samePoint(here, this.markerAt)) this.marker.setLatLng(here);
      this.markerAt = here;
      const el = this.marker.getElement();
      if (el) {
        // to the degree: finer does not show on a 28 px arrow
        setStyle(el.querySelector("svg"), "transform", `rotate(${Math.round(this.turnTo(heading))}deg)`);
        setAttr(el, "data-category", category(state));
        el.classList.toggle("selected", selected);
        el.classList.toggle("stale", !state.connected);
        setAttr(el, "data-heading-deg", num(heading, 0));
      }
      this.addToTrail(here, nowS);
    }
    const home = homeLatLon(state);
    this.show(this.home, Boolean(home));
    if (home && !samePoint(home, this.homeAt)) this.home.setLatLng(home);
    this.homeAt = home;

    const aim = aimOf(state);
    const origin = aim && nedOrigin(state);
    const point = origin ? offsetLatLon(origin, aim.north_m, aim.east_m) : null;
    this.show(this.aim, Boolean(point));
    this.show(this.aimLine, Boolean(point && here));
    if (point) {
      if (!samePoint(point, this.aimLatLon)) this.aim.setLatLng(point);
      setAttr(this.aim.getElement(), "data-kind", aim.kind);
      if (here && !(samePoint(here, this.aimFrom) && samePoint(point, this.aimLatLon))) {
        this.aimLine.setLatLngs([here, point]);
      }
    }
    this.aimFrom = here;
    this.aimLatLon = point;
    this.aimKind = aim?.kind ?? null;
  }

  /** The arrow's angle for a heading: turned the short way from the last one (359° to 1°
   * is 2°, not a spin back through 180° while the CSS transition runs). */
  turnTo(headingDeg) {
    if (!Number.isFinite(headingDeg)) return this.arrowDeg ?? 0;
    if (this.arrowDeg === undefined) this.arrowDeg = headingDeg;
    else this.arrowDeg += ((headingDeg - this.arrowDeg + 540) % 360) - 180;
    return this.arrowDeg;
  }

  addToTrail(here, nowS) {
    const last = this.trail[this.trail.length - 1];
    const moved = !last || offsetDistanceM(last, here) >= TRAIL_MIN_STEP_M;
    if (moved) this.trail.push([here[0], here[1], nowS]);
    while (this.trail.length && nowS - this.trail[0][2] > TRAIL_S) this.trail.shift();
    const dropped = this.trail.length !== this.trailDrawn;
    if (moved || dropped) {
      this.trailLine.setLatLngs(this.trail.map(([lat, lon]) => [lat, lon]));
      this.trailDrawn = this.trail.length;
    }
    this.show(this.trailLine, this.trail.length > 1);
  }

  remove() {
    this.group.remove();
  }
}

function offsetDistanceM(a, b) {
  return WGS84.Inverse(a[0], a[1], b[0], b[1]).s12;
}

// ---- the metre grid (offline) --------------------------------------------------------------

/** Grid step for a view `spanM` metres across: the smallest that draws at most
 * GRID_MAX_LINES lines. */
export function gridStepM(spanM) {
  return GRID_STEPS_M.find((step) => spanM / step <= GRID_MAX_LINES) ?? null;
}

class MetreGrid {
  constructor(map) {
    this.map = map;
    this.layer = L.layerGroup().addTo(map);
    this.ref = null;
    this.stepM = null;
    this.label = L.control({ position: "bottomleft" });
    this.label.onAdd = () => L.DomUtil.create("div", "map-grid-label");
    this.label.addTo(map);
    this.redraw = () => this.draw();
    map.on("moveend zoomend resize", this.redraw);
  }

  setReference(ref) {
    if (this.ref && offsetDistanceM(this.ref, ref) < 0.5) return;
    this.ref = ref;
    this.draw();
  }

  draw() {
    this.layer.clearLayers();
    const labelEl = this.label.getContainer();
    if (!this.ref) { labelEl.textContent = ""; return; }
    const b = this.map.getBounds();
    const corners = [b.getNorthWest(), b.getNorthEast(), b.getSouthWest(), b.getSouthEast()]
      .map((c) => offsetOf(this.ref, [c.lat, c.lng]));
    const n = corners.map((c) => c.north_m);
    const e = corners.map((c) => c.east_m);
    const [nMin, nMax, eMin, eMax] = [Math.min(...n), Math.max(...n), Math.min(...e), Math.max(...e)];
    const step = gridStepM(Math.max(nMax - nMin, eMax - eMin));
    this.stepM = step;
    labelEl.textContent = step ? `grid ${step >= 1000 ? `${step / 1000} km` : `${step} m`}` : "";
    if (!step) return;
    const lines = [];
    for (let k = Math.ceil(nMin / step); k <= Math.floor(nMax / step); k++) {
      lines.push([k === 0, [offsetLatLon(this.ref, k * step, eMin), offsetLatLon(this.ref, k * step, eMax)]]);
    }
    for (let k = Math.ceil(eMin / step); k <= Math.floor(eMax / step); k++) {
      lines.push([k === 0, [offsetLatLon(this.ref, nMin, k * step), offsetLatLon(this.ref, nMax, k * step)]]);
    }
    for (const [axis, points] of lines) {
      this.layer.addLayer(L.polyline(points, {
        className: axis ? "map-grid axis" : "map-grid", interactive: false,
      }));
    }
  }

  remove() {
    this.layer.remove();
    this.label.remove();
    this.map.off("moveend zoomend resize", this.redraw);
  }
}

// ---- controls ------------------------------------------------------------------------------

function northArrow() {
  const control = L.control({ position: "topright" });
  control.onAdd = () => {
    const el = L.DomUtil.create("div", "map-north");
    el.title = "north is up";
    el.innerHTML = '<svg viewBox="-10 -14 20 28" aria-hidden="true"><path d="M0,-13 L7,7 L0,3 L-7,7 Z"/></svg><b>N</b>';
    return el;
  };
  return control;
}

function followButton(onToggle) {
  const control = L.control({ position: "topleft" });
  control.onAdd = () => {
    const button = L.DomUtil.create("button", "map-follow");
    button.type = "button";
    button.id = "map-follow";
    button.title = "keep the selected vehicle in view (C)";
    button.textContent = "Follow";
    L.DomEvent.disableClickPropagation(button);
    button.addEventListener("click", () => onToggle());
    return button;
  };
  return control;
}

// ---- the map -------------------------------------------------------------------------------

export class VehicleMap {
  constructor(container) {
    this.container = container;
    this.map = L.map(container, {
      zoomControl: true, maxZoom: MAX_ZOOM, zoomSnap: 0.5, worldCopyJump: true,
      attributionControl: true, keyboard: false, // the arrow keys fly the vehicle
    }).setView([0, 0], 2);
    this.map.attributionControl.setPrefix('<a href="https://leafletjs.com">Leaflet</a>');
    L.control.scale({ imperial: false, maxWidth: 140 }).addTo(this.map);
    northArrow().addTo(this.map);
    this.followControl = followButton(() => this.setFollow(!this.follow));
    this.followControl.addTo(this.map);
    this.layers = new Map();
    this.grid = new MetreGrid(this.map);
    this.tiles = null;
    this.placed = false;
    this.others = null;
    this.pick = L.circleMarker([0, 0], { radius: 7, className: "map-pick", interactive: false });
    // states are kept as they come and drawn at most ten times a second while the map shows
    this.pending = new Map();
    this.painter = new Painter("map", () => this.drawPending(), {
      shown: boxShown(container),
    });
    this.setFollow(true);
    this.map.on("dragstart", () => this.setFollow(false));
    this.map.on("click", (e) => this.offerGoto(e.latlng));
    new ResizeObserver(() => {
      this.map.invalidateSize({ pan: false });
      this.painter.wake(); // shown again: what came meanwhile, at once
    }).observe(container);
  }

  /** Tiles when the server has a map_tile_url or a tile archive; the grid stays otherwise.
   * Returns the server's page configuration (null when it gave none). */
  async loadConfig() {
    let config = null;
    try {
      config = await callApi("page_config");
    } catch {
      return null; // an older server: the grid
    }
    if (!config?.map_tile_url) return config;
    // an offline archive (map_tiles) says which zooms and area it holds: no asking past them
    const [west, south, east, north] = config.map_tile_bounds || [];
    this.tiles = L.tileLayer(config.map_tile_url, {
      maxZoom: MAX_ZOOM, maxNativeZoom: config.map_tile_max_zoom ?? TILE_MAX_NATIVE_ZOOM,
      minZoom: config.map_tile_min_zoom ?? 0,
      attribution: config.map_tile_attribution || "",
      ...(config.map_tile_bounds ? { bounds: L.latLngBounds([south, west], [north, east]) } : {}),
    }).addTo(this.map);
    this.container.classList.add("with-tiles");
    this.grid.remove();
    this.grid = null;
    return config;
  }

  setFollow(on) {
    this.follow = on;
    this.followControl.getContainer()?.classList.toggle("on", on);
    if (on) this.centreOnSelected();
  }

  centreOnSelected() {
    const here = this.layers.get(page.vehicleId)?.latLon;
    if (here) this.map.panTo(here, { animate: false });
  }

  /** Every state message of the page's socket, and of the others' socket; a fleet
   * vehicle's (fleet.js) under its key "edge/id". */
  onState(state, id = state.vehicle ?? state.id) {
    this.pending.set(id, state);
    this.painter.request();
  }

  drawPending() {
    const states = [...this.pending];
    this.pending.clear();
    for (const [id, state] of states) this.drawState(state, id);
  }

  drawState(state, id) {
    if (!this.knows(id)) return;
    let layer = this.layers.get(id);
    if (!layer) {
      layer = new VehicleLayer(this.map, id, (picked) => this.selectVehicle(picked));
      this.layers.set(id, layer);
    }
    const selected = id === page.vehicleId;
    layer.update(state, selected, performance.now() / 1000);
    if (!selected) return;
    const home = homeLatLon(state);
    if (home && this.grid) this.grid.setReference(home);
    if (!this.placed && layer.latLon) {
      this.placed = true;
      this.map.setView(layer.latLon, FIRST_ZOOM, { animate: false });
    } else if (this.follow && layer.latLon && !this.map.getBounds().pad(-0.25).contains(layer.latLon)) {
      this.map.panTo(layer.latLon, { animate: false });
    }
  }

  knows(id) {
    if (typeof id === "string") return true; // a fleet vehicle: the fleet view lists them
    return page.vehicles.length === 0 || page.vehicles.some((v) => v.id === id);
  }

  /** The server's vehicle list changed: forget vanished vehicles; with more than one, watch
   * the others too. */
  showVehicles(vehicles) {
    const ids = new Set(vehicles.map((v) => v.id));
    for (const [id, layer] of this.layers) {
      if (typeof id === "number" && !ids.has(id)) { layer.remove(); this.layers.delete(id); }
    }
    if (vehicles.length > 1 && !this.others && !page.rejected) {
      this.others = new TelemetrySocket(null, {
        rateHz: OTHERS_RATE_HZ,
        onStatus: () => {},
        onMessage: (m) => { if (m.type === "state" && m.vehicle !== page.vehicleId) this.onState(m); },
      });
    } else if (vehicles.length <= 1 && this.others) {
      this.stop();
    }
  }

  vehicleChanged() {
    for (const [id, layer] of this.layers) {
      layer.marker.getElement()?.classList.toggle("selected", id === page.vehicleId);
    }
    this.setFollow(true);
  }

  selectVehicle(id) {
    if (id === page.vehicleId) return;
    if (typeof id === "string") { // a fleet vehicle
      document.dispatchEvent(new CustomEvent("skyhelm-fleet-select", { detail: id }));
      return;
    }
    const select = $("vehicle-select");
    select.value = String(id);
    select.dispatchEvent(new Event("change"));
  }

  stop() {
    this.others?.close();
    this.others = null;
  }

  // ---- reposition by click -----------------------------------------------------------------

  defaultAltitudeM() {
    const alt = page.state?.global?.alt_rel_m;
    if (Number.isFinite(alt) && alt > 1) return Math.round(alt * 2) / 2;
    const typed = parseFloat($("repo-alt").value);
    return Number.isFinite(typed) ? typed : 10;
  }

  offerGoto(latlng) {
    const target = [latlng.lat, latlng.lng];
    const here = this.layers.get(page.vehicleId)?.latLon;
    const box = L.DomUtil.create("div", "map-goto");
    box.id = "map-goto";
    const away = here ? ` · ${num(offsetDistanceM(here, target), 0)} m away` : "";
    box.innerHTML = `<div class="map-goto-title">Fly vehicle ${page.vehicleId ?? "–"} here?</div>`
      + `<div class="map-goto-where">${num(target[0], 6)}, ${num(target[1], 6)}${away}</div>`
      + '<div class="row"><label class="field">alt <input id="map-goto-alt" class="num" type="number" step="0.5" min="1"> m above home</label></div>'
      + '<div class="row"><button id="map-goto-go" class="primary">Fly here</button>'
      + '<button id="map-goto-cancel">Cancel</button></div>'
      + '<div id="map-goto-note" class="hint"></div>';
    const alt = box.querySelector("#map-goto-alt");
    alt.value = this.defaultAltitudeM();
    const go = box.querySelector("#map-goto-go");
    const note = box.querySelector("#map-goto-note");
    const allowed = inControl() && page.vehicleId !== null;
    go.disabled = !allowed;
    go.setAttribute("aria-describedby", "map-goto-note");
    note.textContent = allowed ? "the server's goto intent, checked against the envelope" : "take control to fly there";
    this.pick.setLatLng(target).addTo(this.map);
    const popup = L.popup({ className: "map-goto-popup", minWidth: 220, autoPanPadding: [20, 20] })
      .setLatLng(latlng).setContent(box).openOn(this.map);
    popup.on("remove", () => this.pick.remove());
    box.querySelector("#map-goto-cancel").addEventListener("click", () => this.map.closePopup(popup));
    const fly = async () => {
      const altM = parseFloat(alt.value);
      if (Number.isFinite(altM) && !(await altitudeAllowed("Go to the map point", altM))) {
        note.textContent = "cancelled: the altitude was not confirmed";
        return;
      }
      go.disabled = true;
      note.textContent = "sent, waiting for the vehicle…";
      const answer = await runCommand("Go to the map point", "goto", {
        lat_deg: target[0], lon_deg: target[1], alt_rel_m: Number.isFinite(altM) ? altM : null,
      }, go);
      if (answer?.ok) {
        this.map.closePopup(popup);
      } else {
        go.disabled = !inControl();
        note.textContent = $("result").textContent;
      }
    };
    go.addEventListener("click", fly);
    alt.addEventListener("keydown", (e) => { if (e.key === "Enter" && !go.disabled) fly(); });
    L.DomEvent.disableClickPropagation(box);
  }

  /** For the tests: where a lat/lon is on the page, in CSS pixels. */
  pagePoint(lat, lon) {
    const p = this.map.latLngToContainerPoint([lat, lon]);
    const r = this.container.getBoundingClientRect();
    return { x: r.left + p.x, y: r.top + p.y };
  }
}
