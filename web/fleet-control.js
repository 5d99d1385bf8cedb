// Flying a fleet vehicle: the same interface as the control socket's ControlSession (api.js),
// over the fleet server's proxied REST routes (/api/v1/fleet/edges/{edge}/vehicles/{id}/…),
// so every panel of the page flies a vehicle of another edge exactly as a local one. The
// lease is REST's: taken with the acquire call, carried as X-Lease-Id on every call (which
// renews it) and renewed with the renew call while the tab is open; the edge checks all of it.

import { ApiError, LeaseSession, callApi, unanswered } from "./api.js";
// the control socket's command names as REST calls, those without a body, and every call's
// method and path (generated from the wire's call table: python -m tools.gen_calls_js)
import { COMMANDS, FLEET_VEHICLE_PATH, NO_BODY } from "./calls.js";

// renew at a third of the TTL: two renewals may be lost before the lease lapses
const RENEW_FRACTION = 1 / 3;

/** The fleet server's path of the vehicle of an edge (FLEET_VEHICLE_PATH filled in). */
function fleetVehiclePath(vehicle, suffix = "") {
  return FLEET_VEHICLE_PATH.replace("{edge}", encodeURIComponent(vehicle.edge))
    .replace("{vehicle_id}", encodeURIComponent(vehicle.id)) + suffix;
}

export class FleetControlSession extends LeaseSession {
  constructor(vehicle, { takeover = false, force = false, clientName, onLease, onClosed, onMessage }) {
    super({ onLease, onClosed, onMessage });
    this.vehicle = vehicle;
    this.ended = false;
    this.renewTimer = null;
    this.clientName = clientName;
    this.acquire({ client_name: clientName, ...(takeover ? { takeover: true } : {}), ...(force ? { force: true } : {}) });
  }

  path(suffix = "") {
    return fleetVehiclePath(this.vehicle, suffix);
  }

  /** The call `name` of the wire's table on this vehicle, through its edge. */
  leaseCall(name, body, leaseId) {
    return callApi(name, { vehicle: this.path(), body, headers: leaseId ? { "X-Lease-Id": leaseId } : {} });
  }

  async acquire(body) {
    try {
      const lease = await this.leaseCall("acquire", body);
      if (this.ended) { // closed while the edge was answering: give it back
        this.leaseCall("release", undefined, lease.lease_id).catch(() => {});
        return;
      }
      this.scheduleRenew(lease.ttl_s);
      this.granted(lease);
    } catch (err) {
      const reason = err.body?.detail?.reason || err.message;
      // the control socket's close codes, so handover.js tells the pilot the same things
      const code = { 409: 4409, 403: 4403, 401: 4401 }[err.status] ?? 1011;
      this.finish({ code, reason, refusal: { reason } });
    }
  }

  scheduleRenew(ttlS) {
    clearTimeout(this.renewTimer);
    const everyMs = Math.max(500, (Number(ttlS) || 30) * 1000 * RENEW_FRACTION);
    this.renewTimer = setTimeout(() => this.renew(), everyMs);
  }

  async renew() {
    if (this.ended || !this.leaseId) return;
    try {
      const lease = await this.leaseCall("renew", {}, this.leaseId);
      this.holder = lease.holder;
      this.scheduleRenew(lease.ttl_s);
    } catch (err) {
      this.lostLease(err);
    }
  }

  /** A 423 from the edge: the lease is gone (lapsed, released elsewhere, taken over). */
  lostLease(err) {
    if (err.status === 423) {
      const by = err.body?.detail?.holder;
      this.finish({ code: 4408, reason: err.message, ended: by ? { state: "taken_over", by } : { state: "expired" } });
    } else if (!this.ended) {
      this.scheduleRenew(this.lease?.ttl_s); // a blip of the fleet link: try again
    }
  }

  finish(info) {
    if (this.ended) return;
    this.ended = true;
    clearTimeout(this.renewTimer);
    this.leaseId = null;
    this.onClosed({ byUs: false, ...info });
  }

  get open() {
    return !this.ended && this.leaseId !== null;
  }

  /** The call `name` (with its path's `params`) under the lease: its answer as the control
   * socket's. */
  async call(name, body, params) {
    if (!this.open) return unanswered("not in control");
    try {
      const answer = await callApi(name, { vehicle: this.path(), params, body, headers: { "X-Lease-Id": this.leaseId } });
      this.scheduleRenew(this.lease?.ttl_s); // every control call renews the lease
      return { ok: true, status: 200, body: answer };
    } catch (err) {
      if (!(err instanceof ApiError)) throw err;
      if (err.status === 423) this.lostLease(err);
      return { ok: false, status: err.status, body: err.body };
    }
  }

  /** A command or an intent, by its control-socket name. */
  command(name, args = {}) {
    if (!COMMANDS[name]) return Promise.resolve({ ok: false, status: 422, body: { detail: { reason: `unknown command ${name}`, field: "name" } } });
    return this.call(name, NO_BODY.has(name) ? undefined : args);
  }

  setpoint(setpoint) {
    return this.call("set_setpoint", setpoint);
  }

  /** The control socket's other messages: sticks (fly_sticks / stop_sticks). */
  send(message) {
    if (message.type === "command") return this.command(message.name, message.args);
    if (message.type === "setpoint") return this.setpoint(message.setpoint);
    if (message.type === "sticks") {
      return message.stop ? this.call("stop_sticks") : this.call("fly_sticks", message.sticks);
    }
    return Promise.resolve(unanswered(`not over the fleet: ${message.type}`, 422));
  }

  answerTakeover(requestId, grant) {
    return this.call("answer_takeover", { grant }, { request_id: requestId });
  }

  close() {
    if (this.ended) return;
    const leaseId = this.leaseId;
    this.finish({ code: 1000, byUs: true });
    if (leaseId) this.leaseCall("release", undefined, leaseId).catch(() => {});
  }
}
