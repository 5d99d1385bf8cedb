// Drawing at the pace a person can see: a part of the page (the state's numbers, the plots,
// the map) asks to be drawn when what it shows changed; it is drawn at once, never twice
// within `minGapMs` (a change that comes sooner is drawn when that time is up), never while
// the page is hidden (document.visibilityState) or the part itself is hidden, and at once
// when it shows again.
// Parts drawn at a slower pace (the plots, running counters) keep one beat
// (SLOW_BEAT_MS), so they change in the same frames.
// The parts due together are drawn at the end of the task that asked for them (a microtask:
// a state is drawn as its message is handled, not after whatever other tasks a busy page has
// queued meanwhile): no requestAnimationFrame at all (each one asks the browser for a frame,
// which costs even when nothing changed, and a window the browser gives few frames, headless
// Chromium's second page, would lag); what a draw changes is painted in the browser's next
// frame.
//
// window.skyhelm.draws counts the draws of each part and window.skyhelm.drawTimes keeps
// when (performance.now(), the last DRAW_TIMES_KEPT) it drew, for the browser tests and the
// console.

export const SLOW_BEAT_MS = 500;
export const draws = {};
export const drawTimes = {};
const DRAW_TIMES_KEPT = 100;
const painters = [];
const due = new Set();
let task = false; // a drawDue() queued

export const pageHidden = () => document.visibilityState === "hidden";

function drawDue() {
  task = false;
  const now = performance.now();
  for (const painter of [...due]) {
    due.delete(painter);
    painter.run(now);
  }
}

export class Painter {
  /** `draw()` draws the part; `shown()` says whether the part can be seen now. With `beatMs`,
   * a draw that has to wait waits for the next multiple of it on the page's clock, so the
   * parts drawn at the same pace change in the same frame (each frame that changes anything
   * is laid out, painted and composited as a whole). */
  constructor(name, draw, { minGapMs = 100, shown = () => true, beatMs = 0 } = {}) {
    this.name = name;
    this.draw = draw;
    this.minGapMs = minGapMs;
    this.beatMs = beatMs;
    this.shown = shown;
    this.dirty = false;
    this.lastMs = -Infinity;
    this.timer = null;
    draws[name] = 0;
    drawTimes[name] = [];
    painters.push(this);
  }

  /** What this part shows changed: draw it soon. */
  request() {
    this.dirty = true;
    this.plan();
  }

  plan() {
    if (!this.dirty || this.timer !== null || due.has(this)) return;
    if (pageHidden() || !this.shown()) return; // drawn when shown again (wake())
    let atMs = this.lastMs + this.minGapMs;
    if (this.beatMs > 0 && Number.isFinite(atMs)) atMs = Math.ceil(atMs / this.beatMs) * this.beatMs;
    const waitMs = atMs - performance.now();
    if (waitMs > 0) {
      // on a beat, the beat counts as the time drawn (a timer fires a little late)
      const beat = this.beatMs > 0 ? atMs : undefined;
      this.timer = setTimeout(() => { this.timer = null; this.run(performance.now(), beat); }, waitMs);
      return;
    }
    due.add(this);
    if (!task) {
      task = true;
      queueMicrotask(drawDue);
    }
  }

  run(now, beatMs = now) {
    if (!this.dirty || pageHidden() || !this.shown()) return;
    this.dirty = false;
    this.lastMs = beatMs;
    draws[this.name] += 1;
    const times = drawTimes[this.name];
    times.push(now);
    if (times.length > DRAW_TIMES_KEPT) times.shift();
    try { this.draw(); } catch (err) { console.error(err); }
  }

  /** Shown again (the page or the part): what changed meanwhile is drawn at once. */
  wake() {
    if (!this.dirty) return;
    this.lastMs = -Infinity;
    clearTimeout(this.timer);
    this.timer = null;
    this.plan();
  }
}

/** Every part shown again: those that changed while hidden catch up in the next frame. */
export function wakeAll() {
  for (const painter of painters) painter.wake();
}

document.addEventListener("visibilitychange", () => { if (!pageHidden()) wakeAll(); });

/** Whether `element` can be seen: it has a box (neither it nor a parent is display: none).
 * Kept by a ResizeObserver, so asking reads no layout (Element.checkVisibility() brings style
 * and layout up to date: asked at every state, after the state's text was written, a layout
 * of the whole page in the middle of a task). `onShown()` runs when it gets its box again. */
export function boxShown(element, onShown = () => {}) {
  let shown = true; // until the first observation, in the next frame
  new ResizeObserver((entries) => {
    const { width, height } = entries.at(-1).contentRect;
    const was = shown;
    shown = width > 0 || height > 0;
    if (shown && !was) onShown();
  }).observe(element);
  return () => shown;
}

/** Sets an attribute only when its value changes (every set is a DOM mutation). */
export function setAttr(el, name, value) {
  if (el && el.getAttribute(name) !== value) el.setAttribute(name, value);
}

/** Sets one inline style property only when it changes. */
export function setStyle(el, property, value) {
  if (el && el.style[property] !== value) el.style[property] = value;
}
