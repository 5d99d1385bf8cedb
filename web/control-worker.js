// The control socket lives in this worker so that its heartbeats keep the lease while the
// page's main thread is busy (software WebGL rendering the 3D scene can stall it for
// seconds). The page must still show signs of life: without a ping from it for
// PAGE_SILENCE_MS the worker stops heartbeating and the server's deadman takes over.

const PAGE_SILENCE_MS = 10000;
let ws = null;
let heartbeat = null;
let lastPagePing = Date.now();

function post(ev, extra) {
  self.postMessage({ ev, ...extra });
}

self.onmessage = (event) => {
  const msg = event.data;
  lastPagePing = Date.now();
  if (msg.op === "open") {
    ws = new WebSocket(msg.url);
    ws.onopen = () => post("open");
    ws.onmessage = (e) => {
      const data = JSON.parse(e.data);
      if (data.type === "lease" && data.lease_id && !heartbeat) {
        // a quarter of the TTL, at least once a second so a dead socket shows soon
        const everyMs = Math.min(1000, Math.max(100, ((data.ttl_s || 2) * 1000) / 4));
        heartbeat = setInterval(() => {
          if (Date.now() - lastPagePing > PAGE_SILENCE_MS) return;
          if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ type: "heartbeat" }));
        }, everyMs);
      }
      post("message", { data });
    };
    ws.onclose = (e) => {
      clearInterval(heartbeat);
      heartbeat = null;
      post("close", { code: e.code, reason: e.reason });
    };
  } else if (msg.op === "send" && ws && ws.readyState === WebSocket.OPEN) {
    ws.send(msg.text);
  } else if (msg.op === "close" && ws) {
    ws.close(1000, "released");
  }
};
