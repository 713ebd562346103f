// Live graphs under the arm while a recording plays: the five activations (motion-and-load model)
// and the target vs achieved elbow angle, drawn up to the frame on screen. The axes, the shading
// of clamped / not-holdable frames and the target are drawn once per recording; each frame adds
// only the new segments (a few lines of canvas work, not a redraw).
import { SWATCH } from './ui.js';

const PAD = { left: 38, right: 10, top: 18, bottom: 20 };

export class Graphs {
  constructor(canvas, muscles) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.muscles = muscles;
    this.rec = null;
    this.drawn = 0; // frames drawn so far
    this.updates = 0;
  }

  show(rec) {
    this.rec = rec;
    this.canvas.parentElement.hidden = false;
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    this.canvas.width = w; this.canvas.height = h;
    const half = Math.floor(w / 2);
    this.panels = [{ x: 0, w: half, y0: 0, y1: 1, title: 'activations (motion-and-load model)' },
      { x: half, w: w - half, y0: rec.range[0] - 5, y1: rec.range[1] + 5, title: 'elbow angle (deg): target - - , achieved —' }];
    this.background();
  }

  hide() { this.canvas.parentElement.hidden = true; this.rec = null; }

  xy(p, t, v) {
    const { rec } = this, h = this.canvas.height;
    const x = p.x + PAD.left + ((t - rec.time[0]) / Math.max(rec.duration, 1e-9)) * (p.w - PAD.left - PAD.right);
    const y = PAD.top + (1 - (v - p.y0) / (p.y1 - p.y0)) * (h - PAD.top - PAD.bottom);
    return [x, y];
  }

  background() {
    const { ctx, rec } = this, h = this.canvas.height;
    ctx.clearRect(0, 0, this.canvas.width, h);
    ctx.font = '11px system-ui, sans-serif';
    for (const p of this.panels) {
      ctx.fillStyle = '#98a2b3';
      ctx.fillText(p.title, p.x + PAD.left, 12);
      // shading: frames clamped to the reachable range (grey), frames the muscles cannot hold (red)
      for (const [mask, colour] of [[rec.clamped, 'rgba(160,170,185,0.18)'], [rec.notHeld, 'rgba(255,90,90,0.22)']]) {
        ctx.fillStyle = colour;
        for (let k = 0; k < mask.length; k++) {
          if (!mask[k]) continue;
          const [x0] = this.xy(p, rec.time[k], p.y0), [x1] = this.xy(p, rec.time[Math.min(k + 1, mask.length - 1)], p.y0);
          ctx.fillRect(x0, PAD.top, Math.max(1, x1 - x0), h - PAD.top - PAD.bottom);
        }
      }
      ctx.strokeStyle = '#2f3947';
      ctx.strokeRect(p.x + PAD.left, PAD.top, p.w - PAD.left - PAD.right, h - PAD.top - PAD.bottom);
      ctx.fillStyle = '#98a2b3';
      for (const v of [p.y0, (p.y0 + p.y1) / 2, p.y1]) {
        const [, y] = this.xy(p, rec.time[0], v);
        ctx.fillText(v.toFixed(p.y1 > 2 ? 0 : 1), p.x + 4, y + 4);
      }
      const [, yb] = this.xy(p, rec.time[0], p.y0);
      ctx.fillText(`${rec.duration.toFixed(1)} s`, p.x + p.w - PAD.right - 30, yb + 14);
    }
    this.line(this.panels[1], rec.target, 0, rec.target.length - 1, '#e6e9ee', [4, 3]);
    this.drawn = 0;
  }

  line(p, values, from, to, colour, dash = []) {
    if (to <= from) return;
    const { ctx, rec } = this;
    ctx.strokeStyle = colour; ctx.lineWidth = 1.5; ctx.setLineDash(dash);
    ctx.beginPath();
    for (let k = from; k <= to; k++) {
      const [x, y] = this.xy(p, rec.time[k], values[k]);
      if (k === from) ctx.moveTo(x, y); else ctx.lineTo(x, y);
    }
    ctx.stroke();
    ctx.setLineDash([]);
  }

  // Draw up to frame k (achieved angles known up to there). A restart (k behind) redraws.
  update(k) {
    if (!this.rec) return;
    if (k < this.drawn) this.background();
    const from = Math.max(0, this.drawn - 1);
    if (k <= from) return;
    const rec = this.rec;
    for (let m = 0; m < this.muscles.length; m++) this.line(this.panels[0], rec.effortOf[m], from, k, SWATCH[m]);
    this.line(this.panels[1], rec.achieved, from, k, '#4fb3ff');
    this.drawn = k;
    this.updates++;
  }
}
