// Paces the frames of the 3D scene's client (viser's three.js canvas, in the page's frame).
// viser renders on demand, but each change it is sent opens 250 ms of frames at the display's
// rate, and it asks one frame a second while nothing changes ("a safety net"); without a GPU
// each frame is software-rendered, which is most of what the 3D view costs. This script runs
// in the scene's document before viser's own (the server puts it in the page it serves) and
// holds the document's animation frames to what a pilot can see change:
// - while the pilot drives the view (pointer, click, wheel, keys, a resize) and INTERACTION_MS
//   after, every frame the client asks for, as without this script;
// - for SETTLE_MS after anything reached the client (a scene message from its socket's
//   worker, a fetch done), frames at most every FRAME_GAP_MS (the rate the scene is sent at);
// - otherwise a frame asked for waits (it is not dropped) until one of the above, or at most
//   IDLE_FRAME_MS: viser's idle heartbeat comes every IDLE_FRAME_MS instead of each second.
// A frame held keeps the canvas as it was drawn (nothing in the scene changed meanwhile).
// window.skyhelmScenePace counts frames, messages and interactions, and keeps the times
// (performance.now()) of the last TIMES_KEPT frames and messages, for the tests and the console.
(() => {
  "use strict";
  const FRAME_GAP_MS = 1000 / 30;
  const SETTLE_MS = 400;
  const INTERACTION_MS = 1500;
  const IDLE_FRAME_MS = 10000;
  const START_MS = 3000; // the client starting (its first frames): unpaced
  const TIMES_KEPT = 200;

  const w = window;
  if (w.skyhelmScenePace || typeof w.requestAnimationFrame !== "function") return;
  const nativeRaf = w.requestAnimationFrame.bind(w);
  const stats = {
    frames: 0, messages: 0, interactions: 0, frameTimes: [], messageTimes: [],
    pacedFromMs: performance.now() + START_MS, idleFrameMs: IDLE_FRAME_MS,
  };
  const keep = (times, ms) => {
    times.push(ms);
    if (times.length > TIMES_KEPT) times.shift();
  };
  w.skyhelmScenePace = stats;

  let interactUntil = stats.pacedFromMs;
  let activeUntil = 0;
  let lastFrameMs = -Infinity;
  const waiting = new Map();
  let nextId = 1;
  let native = null;
  let timer = null;

  function runFrame(timestamp) {
    native = null;
    lastFrameMs = performance.now();
    stats.frames += 1;
    keep(stats.frameTimes, lastFrameMs);
    const callbacks = [...waiting.values()];
    waiting.clear();
    for (const callback of callbacks) {
      try {
        callback(timestamp);
      } catch (err) {
        setTimeout(() => { throw err; }); // reported as the browser would, the others run
      }
    }
  }

  function plan() {
    clearTimeout(timer);
    timer = null;
    if (native !== null || waiting.size === 0) return;
    const now = performance.now();
    let dueMs = lastFrameMs + IDLE_FRAME_MS;
    if (now < interactUntil) dueMs = now;
    else if (now < activeUntil) dueMs = lastFrameMs + FRAME_GAP_MS;
    if (dueMs <= now) native = nativeRaf(runFrame);
    else timer = setTimeout(plan, dueMs - now);
  }

  w.requestAnimationFrame = (callback) => {
    const id = nextId++;
    waiting.set(id, callback);
    if (native === null && timer === null) plan();
    return id;
  };
  w.cancelAnimationFrame = (id) => { waiting.delete(id); };

  const changed = () => {
    stats.messages += 1;
    const now = performance.now();
    keep(stats.messageTimes, now);
    activeUntil = now + SETTLE_MS;
    if (native === null) plan();
  };
  const interacted = () => {
    stats.interactions += 1;
    interactUntil = performance.now() + INTERACTION_MS;
    if (native === null) plan();
  };
  // a click too (the page closes viser's WebGL notices with their own button: the notice's
  // exit transition runs on animation frames)
  for (const type of ["pointerdown", "pointermove", "pointerup", "click", "wheel", "keydown",
    "keyup", "touchstart", "touchmove", "resize", "focus"]) {
    w.addEventListener(type, interacted, { capture: true, passive: true });
  }
  document.addEventListener("visibilitychange", interacted);

  // viser's socket lives in a worker: every message from a worker is the scene changing
  const NativeWorker = w.Worker;
  if (typeof NativeWorker === "function") {
    w.Worker = class extends NativeWorker {
      constructor(...args) {
        super(...args);
        this.addEventListener("message", changed);
      }
    };
  }
  const NativeSocket = w.WebSocket;
  if (typeof NativeSocket === "function") {
    w.WebSocket = class extends NativeSocket {
      constructor(...args) {
        super(...args);
        this.addEventListener("message", changed);
      }
    };
  }
  const nativeFetch = w.fetch;
  if (typeof nativeFetch === "function") {
    w.fetch = (...args) => nativeFetch.apply(w, args).finally(changed);
  }
})();
