// The activation graphs while a live source drives the arm: the last WINDOW_S seconds, scrolling,
// in the panel the recordings' graphs use. Left: the five activations (motion-and-load model);
// right: the live elbow angle (dashed), the drawn arm's (solid) and, during an exercise, the
// target (thin). Frames the muscles could not hold are shaded red. Redrawn at most 10 times a
// second from ring buffers (a few hundred points per line).
import { SWATCH } from '../ui.js';

export const WINDOW_S = 10;
const PAD = { left: 38, right: 10, top: 18, bottom: 20 };
const CAP = 2048;
const GAP_S = 0.5;

export class LiveGraphs {
  constructor(canvas, range) {
    this.canvas = canvas;
    this.range = range;
    this.rows = []; // {t, effort[5], angle, achieved, target, notHeld}
    this.drawnAt = 0;
    this.updates = 0;
  }

  show() {
    this.canvas.parentElement.hidden = false;
    this.canvas.width = this.canvas.clientWidth; this.canvas.height = this.canvas.clientHeight;
    const g = this.canvas.getContext('2d');
    g.clearRect(0, 0, this.canvas.width, this.canvas.height);
    g.font = '12px system-ui, sans-serif'; g.fillStyle = '#98a2b3';
    g.fillText('live graphs: waiting for the first elbow sample', PAD.left, this.canvas.height / 2);
  }

  hide() { this.canvas.parentElement.hidden = true; }

  clear() { this.rows = []; }

  add(row) {
    this.rows.push(row);
    if (this.rows.length > CAP) this.rows.splice(0, this.rows.length - CAP);
  }

  draw(now) {
    if (now - this.drawnAt < 100 || !this.rows.length || this.canvas.parentElement.hidden) return;
    this.drawnAt = now;
    this.updates++;
    const { canvas } = this, g = canvas.getContext('2d'), w = canvas.width, h = canvas.height, half = Math.floor(w / 2);
    const tEnd = this.rows[this.rows.length - 1].t, t0 = tEnd - WINDOW_S;
    const rows = this.rows.filter((r) => r.t >= t0);
    // a silence breaks the lines: a gap five times the usual interval (a webcam's frames come a
    // few a second, a tracker's 60), and at least half a second
    const steps = rows.slice(1).map((r, k) => r.t - rows[k].t).sort((a, b) => a - b);
    const gap = Math.max(GAP_S, 5 * (steps[steps.length >> 1] || 0));
    g.clearRect(0, 0, w, h);
    g.font = '11px system-ui, sans-serif';
    const [lo, hi] = [this.range[0] - 5, this.range[1] + 5];
    const panels = [{ x: 0, w: half, y0: 0, y1: 1, title: 'activations, live (motion-and-load model)' },
      { x: half, w: w - half, y0: lo, y1: hi, title: 'elbow angle (deg): live - - , drawn —, target ·' }];
    for (const p of panels) {
      const X = (t) => p.x + PAD.left + ((t - t0) / WINDOW_S) * (p.w - PAD.left - PAD.right);
      const Y = (v) => PAD.top + (1 - (v - p.y0) / (p.y1 - p.y0)) * (h - PAD.top - PAD.bottom);
      g.fillStyle = 'rgba(255,90,90,0.22)';
      for (let k = 0; k + 1 < rows.length; k++) if (rows[k].notHeld) g.fillRect(X(rows[k].t), PAD.top, Math.max(1, X(rows[k + 1].t) - X(rows[k].t)), h - PAD.top - PAD.bottom);
      g.strokeStyle = '#2f3947'; g.lineWidth = 1; g.setLineDash([]);
      g.strokeRect(p.x + PAD.left, PAD.top, p.w - PAD.left - PAD.right, h - PAD.top - PAD.bottom);
      g.fillStyle = '#98a2b3';
      g.fillText(p.title, p.x + PAD.left, 12);
      for (const v of [p.y0, (p.y0 + p.y1) / 2, p.y1]) g.fillText(v.toFixed(p.y1 > 2 ? 0 : 1), p.x + 4, Y(v) + 4);
      g.fillText(`last ${WINDOW_S} s`, p.x + p.w - PAD.right - 50, h - 5);
      const line = (get, colour, dash = [], width = 1.5) => {
        g.strokeStyle = colour; g.lineWidth = width; g.setLineDash(dash); g.beginPath();
        let on = false, last = -Infinity;
        for (const r of rows) {
          const v = get(r);
          if (!Number.isFinite(v)) { on = false; continue; }
          if (on && r.t - last < gap) g.lineTo(X(r.t), Y(v)); else g.moveTo(X(r.t), Y(v)); // no line over a silence
          on = true; last = r.t;
        }
        g.stroke(); g.setLineDash([]);
      };
      if (p.y1 === 1) for (let m = 0; m < 5; m++) line((r) => r.effort[m], SWATCH[m]);
      else {
        line((r) => r.target, '#7fd1ff', [1, 3], 1.2);
        line((r) => r.angle, '#e6e9ee', [4, 3]);
        line((r) => r.achieved, '#4fb3ff');
      }
    }
  }
}
