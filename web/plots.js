// Strip charts drawn on a <canvas>: one value and its setpoint over the last 60 s.

const WINDOW_S = 60;

export class StripChart {
  constructor(canvas, { unit, minSpan = 2 }) {
    this.canvas = canvas;
    this.unit = unit;
    this.minSpan = minSpan;
    this.samples = []; // [time_s, value, setpoint | null]
    this.dirty = true;
  }

  add(timeS, value, setpoint) {
    if (value === null || value === undefined || !Number.isFinite(value)) return;
    this.samples.push([timeS, value, Number.isFinite(setpoint) ? setpoint : null]);
    while (this.samples.length && timeS - this.samples[0][0] > WINDOW_S) this.samples.shift();
    this.dirty = true;
  }

  clear() {
    this.samples = [];
    this.dirty = true;
  }

  draw(nowS) {
    const canvas = this.canvas;
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(10, Math.round(canvas.clientWidth * dpr));
    const h = Math.max(10, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) {
      canvas.width = w;
      canvas.height = h;
    }
    const ctx = canvas.getContext("2d");
    ctx.clearRect(0, 0, w, h);
    const pad = { l: 38 * dpr, r: 6 * dpr, t: 6 * dpr, b: 14 * dpr };
    const values = [];
    for (const [, v, sp] of this.samples) {
      values.push(v);
      if (sp !== null) values.push(sp);
    }
    let lo = values.length ? Math.min(...values) : 0;
    let hi = values.length ? Math.max(...values) : 1;
    if (hi - lo < this.minSpan) {
      const mid = (hi + lo) / 2;
      lo = mid - this.minSpan / 2;
      hi = mid + this.minSpan / 2;
    }
    const margin = (hi - lo) * 0.08;
    lo -= margin;
    hi += margin;
    const x = (t) => pad.l + ((t - (nowS - WINDOW_S)) / WINDOW_S) * (w - pad.l - pad.r);
    const y = (v) => pad.t + (1 - (v - lo) / (hi - lo)) * (h - pad.t - pad.b);

    ctx.font = `${10 * dpr}px sans-serif`;
    ctx.fillStyle = "#8a93a2";
    ctx.strokeStyle = "#262c35";
    ctx.lineWidth = 1;
    for (let i = 0; i <= 4; i++) {
      const v = lo + ((hi - lo) * i) / 4;
      const yy = y(v);
      ctx.beginPath();
      ctx.moveTo(pad.l, yy);
      ctx.lineTo(w - pad.r, yy);
      ctx.stroke();
      ctx.fillText(`${v.toFixed(1)}`, 2 * dpr, yy + 3 * dpr);
    }
    for (let s = 0; s <= WINDOW_S; s += 10) {
      const xx = x(nowS - s);
      ctx.fillText(s === 0 ? "now" : `-${s}s`, xx - (s === 0 ? 18 : 10) * dpr, h - 2 * dpr);
    }
    ctx.fillText(this.unit, pad.l + 4 * dpr, pad.t + 9 * dpr);
    this.line(ctx, x, y, 2, "#f5b041", dpr, [4 * dpr, 3 * dpr]);
    this.line(ctx, x, y, 1, "#5dade2", dpr, []);
    this.dirty = false;
  }

  line(ctx, x, y, index, colour, dpr, dash) {
    ctx.strokeStyle = colour;
    ctx.lineWidth = 1.6 * dpr;
    ctx.setLineDash(dash);
    ctx.beginPath();
    let pen = false;
    for (const sample of this.samples) {
      const v = sample[index];
      if (v === null) {
        pen = false;
        continue;
      }
      if (pen) ctx.lineTo(x(sample[0]), y(v));
      else ctx.moveTo(x(sample[0]), y(v));
      pen = true;
    }
    ctx.stroke();
    ctx.setLineDash([]);
  }
}
