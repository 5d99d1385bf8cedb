// The fleet view of a fleet server (--fleet): every vehicle of every edge, fed by the fleet
// socket (/api/v1/fleet/ws): its edge, how fresh its state is (greyed when stale, LOST when
// its edge's liveliness is gone), who controls it and its mode. Selecting one shows it in the
// instruments and on the map like a local vehicle and flies it through the fleet server's
// proxied REST routes (fleet-control.js). All fleet vehicles are drawn on the 2D map.

import {
  CLOSE_UNAUTHORIZED, callApi, ensureSession, reconnectDelayMs, socketUrl, tokenRejected,
} from "./api.js";
import { age } from "./format.js";
import { page } from "./page.js";
import { log } from "./ui.js";

// the table and the map at this rate per vehicle; the selected vehicle at the socket's rate
const SOCKET_RATE_HZ = 10;
const TABLE_REFRESH_MS = 250;
// state/fast is 10 Hz: older than this and the row greys out
export const STALE_S = 2;

/** A fleet vehicle as the page knows it. */
class FleetEntry {
  constructor(key, edge, id) {
    Object.assign(this, { key, edge, id, alive: false, state: null, ageS: null, receivedS: null });
  }

  /** Seconds since its edge's state was taken, as far as this page can tell. */
  ageNowS(nowS) {
    if (this.receivedS === null) return null;
    return (this.ageS ?? 0) + (nowS - this.receivedS);
  }

  /** The state as the page's renderers read it: a lost vehicle is shown as disconnected. */
  shownState() {
    if (!this.state) return null;
    return {
      ...this.state, type: "state", vehicle: this.key, vehicle_type: this.state.type,
      connected: Boolean(this.state.connected) && this.alive,
    };
  }
}

export class FleetView {
  constructor(panel, map, { onSelect, onSelectedState, onSelectedEvent }) {
    this.panel = panel;
    this.body = panel.querySelector("tbody");
    this.count = panel.querySelector("#fleet-count");
    this.map = map;
    this.onSelect = onSelect;
    this.onSelectedState = onSelectedState;
    this.onSelectedEvent = onSelectedEvent;
    this.vehicles = new Map();
    this.rows = new Map();
    this.socket = null;
    this.attempt = 0;
    this.connected = false;
    this.enabled = false;
  }

  /** Shows the panel and opens the socket on a fleet server; false elsewhere. */
  async start() {
    let config = null;
    try {
      config = await callApi("page_config");
    } catch {
      return false;
    }
    if (!config?.fleet) return false;
    this.enabled = true;
    this.panel.classList.remove("hidden");
    document.body.classList.add("fleet");
    this.connect();
    this.tick = setInterval(() => this.refresh(), TABLE_REFRESH_MS);
    return true;
  }

  connect() {
    if (tokenRejected()) return;
    ensureSession().then(() => this.open(), () => this.retry());
  }

  open() {
    const ws = new WebSocket(socketUrl("fleet", { rate_hz: SOCKET_RATE_HZ }));
    this.socket = ws;
    ws.onmessage = (event) => {
      this.attempt = 0;
      this.connected = true;
      try { this.onMessage(JSON.parse(event.data)); } catch (err) { console.error(err); }
    };
    ws.onclose = (event) => {
      this.connected = false;
      if (event.code !== CLOSE_UNAUTHORIZED) this.retry();
    };
  }

  retry() {
    if (tokenRejected()) return;
    setTimeout(() => this.connect(), reconnectDelayMs(this.attempt++));
  }

  entry(key, edge, id) {
    let entry = this.vehicles.get(key);
    if (!entry) {
      entry = new FleetEntry(key, edge, id);
      this.vehicles.set(key, entry);
    }
    return entry;
  }

  onMessage(message) {
    if (message.type === "fleet_state") {
      const entry = this.entry(message.key, message.edge, message.id);
      entry.alive = Boolean(message.alive);
      entry.state = message.state;
      entry.ageS = Number.isFinite(message.age_s) ? message.age_s : 0;
      entry.receivedS = performance.now() / 1000;
      this.draw(entry);
      if (page.vehicleId === null && !page.rejected) this.select(entry.key);
    } else if (message.type === "presence") {
      this.presence(message);
    } else if (message.type === "event" && message.key === page.fleetVehicle?.key) {
      this.onSelectedEvent(message.event || {});
    }
  }

  presence(message) {
    const alive = Boolean(message.alive);
    const changed = message.id === null || message.id === undefined
      ? [...this.vehicles.values()].filter((v) => v.edge === message.edge && !alive)
      : [this.entry(message.key, message.edge, message.id)];
    for (const entry of changed) {
      if (entry.alive !== alive) log(alive ? "NOTICE" : "WARNING", `fleet: ${entry.key} ${alive ? "back" : "LOST"}`);
      entry.alive = alive;
      this.draw(entry);
    }
  }

  /** The map, and the instruments when it is the selected vehicle. */
  draw(entry) {
    const shown = entry.shownState();
    if (!shown) return;
    this.map.onState(shown, entry.key);
    if (entry.key === page.fleetVehicle?.key) this.onSelectedState(shown);
  }

  select(key) {
    const entry = this.vehicles.get(key);
    if (!entry || key === page.fleetVehicle?.key) return;
    this.onSelect({ key: entry.key, edge: entry.edge, id: entry.id, type: entry.state?.type || "" });
    this.draw(entry);
    this.refresh();
  }

  // ---- the table -----------------------------------------------------------------------------

  refresh() {
    const nowS = performance.now() / 1000;
    const keys = [...this.vehicles.keys()].sort();
    for (const key of keys) this.renderRow(this.vehicles.get(key), nowS);
    const rows = keys.map((key) => this.rows.get(key));
    if (rows.some((row, i) => this.body.children[i] !== row)) this.body.replaceChildren(...rows);
    const alive = [...this.vehicles.values()].filter((v) => v.alive).length;
    this.count.textContent = `${alive} / ${this.vehicles.size} alive${this.connected ? "" : " · reconnecting…"}`;
  }

  renderRow(entry, nowS) {
    let row = this.rows.get(entry.key);
    if (!row) {
      row = document.createElement("tr");
      row.dataset.key = entry.key;
      row.tabIndex = 0;
      for (const name of ["vehicle", "mode", "armed", "age", "control"]) {
        const cell = document.createElement("td");
        cell.className = `fleet-${name}`;
        row.append(cell);
      }
      row.addEventListener("click", () => this.select(entry.key));
      row.addEventListener("keydown", (e) => { if (e.key === "Enter") this.select(entry.key); });
      this.rows.set(entry.key, row);
    }
    const state = entry.state || {};
    const ageS = entry.ageNowS(nowS);
    const stale = entry.alive && (ageS === null || ageS > STALE_S || state.connected === false);
    const cells = row.children;
    setCell(cells[0], `${entry.edge}/${entry.id}`, `${entry.edge} · vehicle ${entry.id}${state.type ? ` · ${state.type}` : ""}`);
    setCell(cells[1], state.mode || "–");
    setCell(cells[2], state.armed ? "ARMED" : state.armed === false ? "disarmed" : "–");
    setCell(cells[3], entry.alive ? age(ageS) : "LOST",
      entry.alive ? (state.connected === false ? "the edge lost its link to the vehicle" : "age of its latest state") : "its edge is gone (liveliness)");
    const holder = state.lease?.holder || null;
    const mine = holder && page.control?.open && page.fleetVehicle?.key === entry.key;
    setCell(cells[4], mine ? "you" : holder || "nobody", holder || "");
    row.classList.toggle("lost", !entry.alive);
    row.classList.toggle("stale", stale);
    row.classList.toggle("armed", Boolean(state.armed));
    row.classList.toggle("selected", entry.key === page.fleetVehicle?.key);
    row.dataset.alive = String(entry.alive);
    row.dataset.ageS = ageS === null ? "" : ageS.toFixed(2);
  }
}

function setCell(cell, text, title) {
  if (cell.textContent !== text) cell.textContent = text;
  if (title !== undefined && cell.title !== title) cell.title = title;
}
