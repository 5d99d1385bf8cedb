// The public SkyHelm API as the page uses it: REST with the bearer token, the telemetry
// socket and the pilot's control socket, both reconnecting by themselves.

export const token = new URLSearchParams(location.search).get("token") || "";
const API = "/api/v1";

export class ApiError extends Error {
  constructor(status, body) {
    super(describeError(status, body));
    this.status = status;
    this.body = body;
  }
}

export function describeError(status, body) {
  const detail = body && body.detail !== undefined ? body.detail : body;
  if (detail && typeof detail === "object") {
    if (Array.isArray(detail)) return detail.map((d) => d.msg || JSON.stringify(d)).join("; ");
    const parts = [detail.reason || detail.result || JSON.stringify(detail)];
    if (detail.field) parts.push(`field ${detail.field}`);
    if (detail.limit !== undefined && detail.limit !== null) parts.push(`limit ${detail.limit}`);
    return `${status}: ${parts.join(", ")}`;
  }
  return `${status}: ${detail ?? "error"}`;
}

export async function request(method, path, body, extraHeaders = {}) {
  const headers = { Authorization: `Bearer ${token}`, ...extraHeaders };
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const response = await fetch(API + path, {
    method, headers, body: body === undefined ? undefined : JSON.stringify(body),
  });
  const text = await response.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch { data = text; }
  if (!response.ok) throw new ApiError(response.status, data);
  return data;
}

function socketUrl(path, params) {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const query = new URLSearchParams({ ...params, token });
  return `${scheme}//${location.host}${API}${path}?${query}`;
}

// Backoff for reconnecting: quick first retry, then up to 3 s.
function retryDelayMs(attempt) {
  return Math.min(3000, 250 * 2 ** attempt);
}

/**
 * Telemetry of one vehicle (or, with vehicleId null, of all): states, events, the vehicle
 * list and scene clicks; calls onMessage for every message and onStatus on changes.
 */
export class TelemetrySocket {
  constructor(vehicleId, { onMessage, onStatus, rateHz = 10 }) {
    this.vehicleId = vehicleId;
    this.onMessage = onMessage;
    this.onStatus = onStatus;
    this.rateHz = rateHz;
    this.closed = false;
    this.attempt = 0;
    this.everConnected = false;
    this.open();
  }

  open() {
    if (this.closed) return;
    const params = { rate_hz: this.rateHz };
    if (this.vehicleId !== null) params.vehicle = this.vehicleId;
    const ws = new WebSocket(socketUrl("/ws/telemetry", params));
    this.ws = ws;
    ws.onopen = () => {
      const again = this.everConnected;
      this.everConnected = true;
      this.attempt = 0;
      this.onStatus({ state: "connected", reconnected: again });
    };
    ws.onmessage = (event) => {
      try { this.onMessage(JSON.parse(event.data)); } catch (err) { console.error(err); }
    };
    ws.onclose = (event) => {
      if (this.closed) return;
      this.onStatus({ state: "lost", code: event.code, reason: event.reason });
      setTimeout(() => this.open(), retryDelayMs(this.attempt++));
    };
  }

  close() {
    this.closed = true;
    if (this.ws) this.ws.close();
  }
}

/**
 * The pilot session: holds the control lease while open and carries setpoints and commands;
 * every message gets its result back (matched by id). The socket and its heartbeats run in
 * control-worker.js; this side pings the worker to show the page is alive.
 */
export class ControlSession {
  constructor(vehicleId, { takeover = false, onLease, onClosed, clientName }) {
    this.vehicleId = vehicleId;
    this.onLease = onLease;
    this.onClosed = onClosed;
    this.pending = new Map();
    this.nextId = 1;
    this.leaseId = null;
    this.ttlS = 2;
    this.socketOpen = false;
    this.closedByUs = false;
    const params = { vehicle: vehicleId };
    if (takeover) params.takeover = "true";
    if (clientName) params.client_name = clientName;
    this.worker = new Worker(new URL("./control-worker.js", import.meta.url), { type: "module" });
    this.worker.onmessage = (event) => this.fromWorker(event.data);
    this.worker.postMessage({ op: "open", url: socketUrl("/ws/control", params) });
    this.alive = setInterval(() => this.worker.postMessage({ op: "alive" }), 1000);
  }

  fromWorker(msg) {
    if (msg.ev === "open") this.socketOpen = true;
    else if (msg.ev === "message") this.receive(msg.data);
    else if (msg.ev === "close") this.closedWith(msg);
  }

  receive(message) {
    if (message.type === "lease" && message.lease_id) {
      this.leaseId = message.lease_id;
      this.ttlS = message.ttl_s || 2;
      this.holder = message.holder;
      this.onLease(message);
    } else if (message.type === "error") {
      this.refusal = message;
    } else if (message.type === "result") {
      const waiter = this.pending.get(message.id);
      if (waiter) {
        this.pending.delete(message.id);
        waiter(message);
      }
    }
  }

  closedWith(event) {
    this.socketOpen = false;
    clearInterval(this.alive);
    this.worker.terminate();
    for (const waiter of this.pending.values()) {
      waiter({ ok: false, status: 0, body: { detail: { reason: "control socket closed" } } });
    }
    this.pending.clear();
    this.leaseId = null;
    this.onClosed({ code: event.code, reason: event.reason, refusal: this.refusal, byUs: this.closedByUs });
  }

  get open() {
    return this.socketOpen && this.leaseId !== null;
  }

  send(message) {
    if (!this.socketOpen) {
      return Promise.resolve({ ok: false, status: 0, body: { detail: { reason: "not in control" } } });
    }
    const id = this.nextId++;
    return new Promise((resolve) => {
      this.pending.set(id, resolve);
      this.worker.postMessage({ op: "send", text: JSON.stringify({ ...message, id }) });
    });
  }

  command(name, args = {}) {
    return this.send({ type: "command", name, args });
  }

  setpoint(setpoint) {
    return this.send({ type: "setpoint", setpoint });
  }

  close() {
    this.closedByUs = true;
    this.worker.postMessage({ op: "close" });
  }
}
