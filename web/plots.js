// Live plots with uPlot (vendored in vendor/uplot/, a global `uPlot`): any numeric telemetry
// field over the last 60 s, picked from a menu per chart. The page keeps 60 s of every field
// (at most 10 samples a second), so a newly picked field shows its past at once. The charts
// are drawn at their own pace (twice a second) while samples come or the last ones scroll
// out, not while the page or the plots are hidden, and not when the picture would not
// change (a flat line across the whole window).

import { Painter, SLOW_BEAT_MS, boxShown } from "./draw.js";
import { num } from "./format.js";

const WINDOW_S = 60;
const SAMPLE_EVERY_S = 0.1;
const DRAW_EVERY_MS = SLOW_BEAT_MS;
const SKIP = new Set(["id", "vehicle", "sysid", "compid", "updated_s"]);
const SKIP_PREFIX = ["statustext", "lease", "telemetry_refused"];
const COLOURS = { value: "#5dade2", setpoint: "#f5b041" };

/** Every finite number in a state, by path: "global.alt_rel_m", "actuator_outputs[2]". */
export function numericFields(value, prefix = "", out = {}) {
  if (typeof value === "number") {
    if (Number.isFinite(value) && prefix && !SKIP.has(prefix)) out[prefix] = value;
  } else if (Array.isArray(value)) {
    value.forEach((v, i) => numericFields(v, `${prefix}[${i}]`, out));
  } else if (value && typeof value === "object") {
    for (const [k, v] of Object.entries(value)) {
      const path = prefix ? `${prefix}.${k}` : k;
      if (!SKIP_PREFIX.some((p) => path.startsWith(p))) numericFields(v, path, out);
    }
  }
  return out;
}

function unitOf(field) {
  const m = /_(m_s|m|deg_s|deg|pct|v|a|s|ms|hz|mah)(\]|$)/.exec(field.replace(/\[\d+\]$/, ""));
  const units = { m_s: "m/s", m: "m", deg_s: "°/s", deg: "°", pct: "%", v: "V", a: "A", s: "s", ms: "ms", hz: "Hz", mah: "mAh" };
  return m ? units[m[1]] : "";
}

class Chart {
  constructor(plots, container, index, field) {
    this.plots = plots;
    this.field = field;
    const pick = document.createElement("div");
    pick.className = "plot-pick";
    this.select = document.createElement("select");
    this.select.id = `plot-field-${index}`;
    this.select.setAttribute("aria-label", `field of plot ${index + 1}`);
    this.select.addEventListener("change", () => this.pick(this.select.value));
    this.latest = document.createElement("b");
    this.latest.className = "plot-latest";
    pick.append(this.select, this.latest);
    this.area = document.createElement("div");
    this.area.className = "plot-area";
    this.area.id = `plot-${index}`;
    container.append(pick, this.area);
    this.uplot = null;
    this.drawn = null; // what a flat line drawn over the whole window showed
    new ResizeObserver(() => this.fit()).observe(this.area);
  }

  make() {
    const { width, height } = this.size();
    const unit = this.plots.unitOf(this.field);
    const axis = { stroke: "#8a93a2", grid: { stroke: "#262c35", width: 1 }, ticks: { stroke: "#262c35" }, font: "10px sans-serif" };
    const options = {
      width, height,
      legend: { show: false },
      cursor: { drag: { x: false, y: false } },
      scales: { x: { time: false, auto: false, range: [-WINDOW_S, 0] }, y: { range: (u, lo, hi) => span(lo, hi) } },
      axes: [
        { ...axis, values: (u, ticks) => ticks.map((t) => (t === 0 ? "now" : `${t}s`)) },
        { ...axis, size: 46, label: unit, labelSize: 12, labelFont: "10px sans-serif", values: (u, ticks) => ticks.map((t) => num(t, Math.abs(t) < 10 ? 1 : 0)) },
      ],
      series: [
        {},
        { label: this.field, stroke: COLOURS.value, width: 1.6, points: { show: false } },
        { label: "setpoint", stroke: COLOURS.setpoint, width: 1.6, dash: [4, 3], points: { show: false } },
      ],
    };
    this.uplot?.destroy();
    this.uplot = new window.uPlot(options, [[], [], []], this.area);
    this.drawn = null;
  }

  size() {
    return { width: Math.max(120, this.area.clientWidth), height: Math.max(60, this.area.clientHeight) };
  }

  fit() {
    if (this.uplot) {
      this.uplot.setSize(this.size());
      this.drawn = null;
    }
  }

  pick(field) {
    this.field = field;
    if (this.select.value !== field) this.select.value = field;
    this.make();
    this.draw(performance.now() / 1000);
  }

  /** The points shown now (for the tests and the console). */
  points() {
    return this.uplot ? this.uplot.data[1].filter((v) => v !== null && Number.isFinite(v)).length : 0;
  }

  draw(nowS) {
    if (!this.uplot) this.make();
    const samples = this.plots.samples;
    const xs = [];
    const ys = [];
    const sps = [];
    const spField = `${this.field}@setpoint`;
    for (const [t, fields] of samples) {
      xs.push(t - nowS);
      ys.push(fields[this.field] ?? null);
      sps.push(fields[spField] ?? null);
    }
    // the same flat line over the whole window: the same picture as drawn, nothing to do
    const full = xs.length > 0 && xs[0] <= -WINDOW_S + 2 * SAMPLE_EVERY_S;
    const flat = full && ys.every((y) => y === ys[0]) && sps.every((y) => y === sps[0]);
    const picture = flat ? `${ys[0]}|${sps[0]}` : null;
    if (picture !== null && picture === this.drawn) return;
    this.drawn = picture;
    this.uplot.setData([xs, ys, sps], false);
    this.uplot.setScale("x", { min: -WINDOW_S, max: 0 });
    this.uplot.redraw(false, true);
    const last = ys.findLast((v) => v !== null);
    const text = last === undefined ? "–" : `${num(last, 2)} ${this.plots.unitOf(this.field)}`.trim();
    if (this.latest.textContent !== text) this.latest.textContent = text;
  }
}

function span(lo, hi) {
  if (lo === null || hi === null) return [0, 1];
  const minSpan = Math.max(0.5, Math.abs(hi) * 0.02);
  if (hi - lo < minSpan) {
    const mid = (hi + lo) / 2;
    return [mid - minSpan / 2, mid + minSpan / 2];
  }
  const margin = (hi - lo) * 0.08;
  return [lo - margin, hi + margin];
}

export class Plots {
  /** derived: {name: {label, unit}} shown first in the menus (fed through add()'s extras). */
  constructor(container, { derived = {}, fields = [] } = {}) {
    this.derived = derived;
    this.samples = []; // [time_s, {field: value}]
    this.known = new Set(Object.keys(derived));
    this.painter = new Painter("plots", () => this.draw(performance.now() / 1000), {
      minGapMs: DRAW_EVERY_MS, beatMs: SLOW_BEAT_MS,
      shown: boxShown(container, () => this.painter.wake()),
    });
    this.charts = fields.map((field, i) => {
      const box = document.createElement("div");
      box.className = "plot";
      container.append(box);
      return new Chart(this, box, i, field);
    });
    this.fillMenus();
  }

  unitOf(field) {
    return this.derived[field]?.unit ?? unitOf(field);
  }

  /** One state at time t (s); extras: {field: [value, setpoint]} computed by the page. */
  add(t, state, extras = {}) {
    const last = this.samples.at(-1);
    if (last && t - last[0] < SAMPLE_EVERY_S) return;
    const fields = numericFields(state);
    for (const [name, [value, setpoint]] of Object.entries(extras)) {
      if (Number.isFinite(value)) fields[name] = value;
      if (Number.isFinite(setpoint)) fields[`${name}@setpoint`] = setpoint;
    }
    this.samples.push([t, fields]);
    while (this.samples.length && t - this.samples[0][0] > WINDOW_S) this.samples.shift();
    let added = false;
    for (const name of Object.keys(fields)) {
      if (!name.endsWith("@setpoint") && !this.known.has(name)) {
        this.known.add(name);
        added = true;
      }
    }
    if (added) this.fillMenus();
    this.painter.request();
  }

  clear() {
    this.samples = [];
    this.painter.request();
  }

  fillMenus() {
    const derived = Object.keys(this.derived);
    const others = [...this.known].filter((f) => !(f in this.derived)).sort();
    for (const chart of this.charts) {
      const options = [...derived, ...others].map((f) => {
        const option = document.createElement("option");
        option.value = f;
        option.textContent = this.derived[f]?.label ?? f;
        return option;
      });
      chart.select.replaceChildren(...options);
      chart.select.value = chart.field;
    }
  }

  draw(nowS) {
    for (const chart of this.charts) chart.draw(nowS);
    // no new sample: the last ones still scroll out of the window, at the same pace
    const last = this.samples.at(-1);
    if (last && nowS - last[0] > 2 * SAMPLE_EVERY_S && nowS - last[0] < WINDOW_S) this.painter.request();
  }
}
