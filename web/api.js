// The public SkyHelm API as the page uses it: REST with the bearer token, the telemetry
// socket and the pilot's control socket, both reconnecting by themselves.

// every call's method and path: the wire's table (python -m tools.gen_calls_js)
import { API_PREFIX as API, SOCKETS, route } from "./calls.js";

const TOKEN_KEY = "skyhelm.token";

/** The token arrives once, in the URL the server printed (?token=…). It leaves the address
 * bar (and the history) at once and stays in this tab's sessionStorage; REST calls send it
 * as a Bearer header, the sockets and the 3D scene carry the session cookie (below). */
function takeToken() {
  const url = new URL(location.href);
  const fromUrl = url.searchParams.get("token");
  let stored = "";
  try {
    if (fromUrl) sessionStorage.setItem(TOKEN_KEY, fromUrl);
    stored = sessionStorage.getItem(TOKEN_KEY) || "";
  } catch { /* storage disabled: the token lives in this page only */ }
  if (fromUrl) {
    url.searchParams.delete("token");
    history.replaceState(history.state, "", url.pathname + url.search + url.hash);
  }
  return fromUrl || stored;
}

export const token = takeToken();

export class ApiError extends Error {
  constructor(status, body) {
    super(describeError(status, body));
    this.status = status;
    this.body = body;
  }
}

/** One line for a refusal: the status, the reason, and what it names (the field and limit
 * of a 422, the holder of a 409/423, the mode a 409 observed). */
export function describeError(status, body) {
  const detail = body && body.detail !== undefined ? body.detail : body;
  if (Array.isArray(detail)) {
    return `${status}: ${detail.map((d) => `${fieldOf(d.loc)}${d.msg || JSON.stringify(d)}`).join("; ")}`;
  }
  if (detail && typeof detail === "object") {
    const parts = [detail.reason || detail.result || JSON.stringify(detail)];
    if (detail.field && !parts[0].includes(detail.field)) parts.push(`field ${detail.field}`);
    if (detail.limit !== undefined && detail.limit !== null) parts.push(`limit ${detail.limit}`);
    if (detail.holder && !parts[0].includes(detail.holder)) parts.push(`held by ${detail.holder}`);
    return `${status}: ${parts.join(", ")}`;
  }
  return `${status}: ${detail ?? "error"}`;
}

function fieldOf(loc) {
  const path = Array.isArray(loc) ? loc.filter((part) => part !== "body") : [];
  return path.length ? `${path.join(".")}: ` : "";
}

// A rejected token stops the page asking: every request and socket checks this first.
let rejected = false;
const rejectedListeners = [];

/** Calls listener(reason) once, when the server first rejects the token (HTTP 401 / WS 4401). */
export function onTokenRejected(listener) {
  rejectedListeners.push(listener);
  if (rejected) listener(rejectedReason);
}

export function tokenRejected() {
  return rejected;
}

let rejectedReason = "";

function reject(reason) {
  if (rejected) return;
  rejected = true;
  rejectedReason = reason;
  for (const listener of rejectedListeners) listener(reason);
}

export async function request(method, path, body, extraHeaders = {}) {
  if (rejected) throw new ApiError(401, { detail: "the token was rejected" });
  const headers = { Authorization: `Bearer ${token}`, ...extraHeaders };
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const response = await fetch(API + path, {
    method, headers, body: body === undefined ? undefined : JSON.stringify(body),
  });
  const text = await response.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch { data = text; }
  if (response.status === 401) reject(describeError(401, data));
  if (!response.ok) throw new ApiError(response.status, data);
  return data;
}

/** The call `name` of the wire's call table (calls.js): a server's call, or a vehicle's
 * under `vehicle`, the vehicle's path (vehiclePath() of page.js); `params` fills the path's
 * {parameters}. */
export function callApi(name, { vehicle = "", params, body, headers } = {}) {
  const [method, path] = route(name, params);
  return request(method, vehicle + path, body, headers);
}

// The session cookie (HttpOnly, SameSite=Strict) for the sockets and the scene, set by
// POST /session with the Bearer token; asked again after a failure.
let session = null;

export function ensureSession() {
  if (!session) {
    const [method, path] = route("open_session");
    session = fetch(API + path, { method, headers: { Authorization: `Bearer ${token}` } })
      .then((response) => {
        if (response.status === 401) reject("the server rejected the token");
        if (!response.ok) throw new Error(`session: HTTP ${response.status}`);
      })
      .catch((err) => {
        session = null;
        throw err;
      });
  }
  return session;
}

// Before the page's modules run: the scene and the first sockets need the cookie.
if (token) {
  try { await ensureSession(); } catch (err) { console.warn(err.message); }
}

/** The URL of the wire's socket `name` ("telemetry", "control", "fleet") with `params`. */
export function socketUrl(name, params) {
  const path = SOCKETS[name];
  if (!path) throw new Error(`no socket ${name} in the wire's table`);
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const query = new URLSearchParams(params);
  return `${scheme}//${location.host}${API}${path}?${query}`;
}

// A hidden page (a background tab) draws nothing: a state a second keeps its alerts (the link
// lost, a failsafe, the battery) and its ages true; events come as they happen at any rate.
export const HIDDEN_RATE_HZ = 1;

/** The telemetry rate for this page now: `visibleHz`, or HIDDEN_RATE_HZ while hidden. */
export function rateForPage(visibleHz) {
  return document.visibilityState === "hidden" ? Math.min(visibleHz, HIDDEN_RATE_HZ) : visibleHz;
}

export const CLOSE_UNAUTHORIZED = 4401;
export const CLOSE_NOT_FOUND = 4404;
export const RECONNECT_FIRST_MS = 500;
export const RECONNECT_MAX_MS = 15000;

/** Reconnect delay before attempt `attempt` (0, 1, …): exponential backoff from
 * RECONNECT_FIRST_MS to RECONNECT_MAX_MS with full jitter, so tabs that lost the same server
 * do not all come back at the same instant. */
export function reconnectDelayMs(attempt, random = Math.random) {
  return random() * Math.min(RECONNECT_MAX_MS, RECONNECT_FIRST_MS * 2 ** attempt);
}

/**
 * Telemetry of one vehicle (or, with vehicleId null, of all): states, events, the vehicle
 * list and scene clicks; calls onMessage for every message and onStatus on changes. The
 * backoff restarts only once a message has arrived: a socket the server accepts and closes
 * at once (no such vehicle yet, a server still starting) keeps backing off.
 */
export class TelemetrySocket {
  constructor(vehicleId, { onMessage, onStatus, rateHz = 10, onChange = true }) {
    this.vehicleId = vehicleId;
    // on_change: the server sends a state when it tells something new (not only that time
    // passed) and twice a second whatever: a landed vehicle's page gets a few states a
    // second instead of ten, and draws, plots and ages them as before (docs/api.md)
    this.onChange = onChange;
    this.onMessage = onMessage;
    this.onStatus = onStatus;
    this.visibleRateHz = rateHz;
    this.rateHz = rateForPage(rateHz);
    this.followVisibility = () => this.setRate(rateForPage(this.visibleRateHz));
    document.addEventListener("visibilitychange", this.followVisibility);
    this.closed = false;
    this.attempt = 0;
    this.retry = null;
    this.everConnected = false;
    this.open();
  }

  open() {
    this.retry = null;
    if (this.closed || rejected) return;
    ensureSession().then(() => this.connect(), (err) => this.lost({ code: 0, reason: err.message }));
  }

  lost(event) {
    if (this.closed || rejected) return;
    const delayMs = reconnectDelayMs(this.attempt++);
    this.onStatus({ state: "lost", code: event.code, reason: event.reason, retryInMs: delayMs });
    this.retry = setTimeout(() => this.open(), delayMs);
  }

  /** States at another rate from now on (a hidden page asks for fewer): a new socket at
   * that rate, the old one closed once the new one speaks, so nothing is missed between
   * (an event may come on both); the page is told of no reconnection. */
  setRate(rateHz) {
    if (rateHz === this.rateHz) return;
    this.rateHz = rateHz;
    if (this.closed || rejected || !this.ws || this.ws.readyState !== WebSocket.OPEN) return;
    const old = this.ws;
    old.onclose = null;
    this.connect(() => old.close());
  }

  connect(whenHeard = null) {
    if (this.closed || rejected) return;
    const params = { rate_hz: this.rateHz };
    if (this.onChange) params.on_change = "true";
    if (this.vehicleId !== null) params.vehicle = this.vehicleId;
    const ws = new WebSocket(socketUrl("telemetry", params));
    this.ws = ws;
    let heard = false;
    ws.onmessage = (event) => {
      if (!heard && whenHeard) {
        heard = true;
        this.attempt = 0;
        whenHeard();
      } else if (!heard) {
        heard = true;
        this.attempt = 0;
        const again = this.everConnected;
        this.everConnected = true;
        this.onStatus({ state: "connected", reconnected: again });
      }
      try { this.onMessage(JSON.parse(event.data)); } catch (err) { console.error(err); }
    };
    ws.onclose = (event) => {
      if (!heard && whenHeard) whenHeard(); // the new one failed: the old one goes too
      if (this.closed) return;
      if (event.code === CLOSE_UNAUTHORIZED) {
        reject(event.reason || "the server rejected the token");
        return;
      }
      this.lost(event);
    };
  }

  close() {
    this.closed = true;
    document.removeEventListener("visibilitychange", this.followVisibility);
    clearTimeout(this.retry);
    if (this.ws) this.ws.close();
  }
}

/** A control session's answer to a call it could not make: a result without a server's. */
export function unanswered(reason, status = 0) {
  return { ok: false, status, body: { detail: { reason } } };
}

/**
 * What every control session (the socket's here, the fleet's REST one in fleet-control.js)
 * keeps for the page: its callbacks and the lease it holds.
 */
export class LeaseSession {
  constructor({ onLease, onClosed, onMessage }) {
    this.onLease = onLease;
    this.onClosed = onClosed;
    this.onMessage = onMessage || (() => {});
    this.leaseId = null;
    this.lease = null;
    this.holder = null;
  }

  /** The lease granted: held from now on, and the page told. */
  granted(lease) {
    this.leaseId = lease.lease_id;
    this.lease = lease;
    this.holder = lease.holder;
    this.onLease(lease);
  }
}

/**
 * The pilot session: holds the control lease while open and carries setpoints, commands and
 * intents; every message gets its result back (matched by id). The socket and its heartbeats
 * run in control-worker.js; this side pings the worker to show the page is alive.
 * `takeover` asks the holder first; with `force` it takes control at once.
 */
export class ControlSession extends LeaseSession {
  constructor(vehicleId, { takeover = false, force = false, clientName, onLease, onClosed, onMessage }) {
    super({ onLease, onClosed, onMessage });
    this.vehicleId = vehicleId;
    this.pending = new Map();
    this.nextId = 1;
    this.ended = null; // the server's last word on the lease: {state, by, …}
    this.socketOpen = false;
    this.closedByUs = false;
    const params = { vehicle: vehicleId };
    if (takeover) params.takeover = "true";
    if (force) params.force = "true";
    if (clientName) params.client_name = clientName;
    this.worker = new Worker(new URL("./control-worker.js", import.meta.url), { type: "module" });
    this.worker.onmessage = (event) => this.fromWorker(event.data);
    ensureSession().then(
      () => this.worker.postMessage({ op: "open", url: socketUrl("control", params) }),
      (err) => this.closedWith({ code: 1006, reason: err.message }),
    );
    this.alive = setInterval(() => this.worker.postMessage({ op: "alive" }), 1000);
  }

  fromWorker(msg) {
    if (msg.ev === "open") this.socketOpen = true;
    else if (msg.ev === "message") this.receive(msg.data);
    else if (msg.ev === "close") this.closedWith(msg);
  }

  receive(message) {
    if (message.type === "lease" && message.lease_id) {
      this.granted(message);
    } else if (message.type === "lease") {
      this.ended = message;
    } else if (message.type === "error") {
      this.refusal = message;
    } else if (message.type === "result") {
      const waiter = this.pending.get(message.id);
      if (waiter) {
        this.pending.delete(message.id);
        waiter(message);
      }
    } else {
      this.onMessage(message);
    }
  }

  closedWith(event) {
    this.socketOpen = false;
    clearInterval(this.alive);
    this.worker.terminate();
    for (const waiter of this.pending.values()) {
      waiter(unanswered("control socket closed"));
    }
    this.pending.clear();
    this.leaseId = null;
    if (event.code === CLOSE_UNAUTHORIZED) reject(event.reason || "the server rejected the token");
    this.onClosed({
      code: event.code, reason: event.reason, refusal: this.refusal, ended: this.ended, byUs: this.closedByUs,
    });
  }

  get open() {
    return this.socketOpen && this.leaseId !== null;
  }

  send(message) {
    if (!this.socketOpen) {
      return Promise.resolve(unanswered("not in control"));
    }
    const id = this.nextId++;
    return new Promise((resolve) => {
      this.pending.set(id, resolve);
      this.worker.postMessage({ op: "send", text: JSON.stringify({ ...message, id }) });
    });
  }

  /** A command or an intent (brake, velocity, offset, goto): the same message on the socket. */
  command(name, args = {}) {
    return this.send({ type: "command", name, args });
  }

  setpoint(setpoint) {
    return this.send({ type: "setpoint", setpoint });
  }

  answerTakeover(requestId, grant) {
    return this.send({ type: "takeover_answer", request_id: requestId, grant });
  }

  close() {
    this.closedByUs = true;
    this.worker.postMessage({ op: "close" });
  }
}
