// The exercise's summary picture (a canvas the page shows and saves as PNG): above, the elbow
// angle against the target over the whole exercise, repetitions numbered, frames the muscles
// could not hold shaded red; below, per repetition the range reached against the target's, the
// duration against the tempo, and the peak and mean effort.

const C = { bg: '#0f1318', fg: '#e6e9ee', dim: '#98a2b3', grid: '#2f3947', user: '#4fb3ff', target: '#7fd1ff',
  peak: '#e76f51', mean: '#e9c46a', bad: 'rgba(255,90,90,0.25)' };

export function drawSummary(canvas, { plan, time, angle, target, notHeld, reps, framesClamped, file }) {
  const g = canvas.getContext('2d'), w = canvas.width, h = canvas.height;
  g.fillStyle = C.bg; g.fillRect(0, 0, w, h);
  g.font = '13px system-ui, sans-serif'; g.fillStyle = C.fg;
  g.fillText(`Exercise: ${plan.reps} × ${plan.lo.toFixed(0)}–${plan.hi.toFixed(0)}°, ${plan.period.toFixed(1)} s each, ` +
    `${plan.load.toFixed(1)} kg — ${reps.length} repetition${reps.length === 1 ? '' : 's'} found` +
    (framesClamped ? `, ${framesClamped} frames clamped to the model's range` : ''), 14, 20);
  g.font = '11px system-ui, sans-serif';
  // top: angle over time
  const top = { x: 46, y: 34, w: w - 60, h: h * 0.45 };
  const t0 = time[0], t1 = Math.max(time[time.length - 1], t0 + 1e-6);
  const lo = Math.min(plan.lo, ...angle) - 5, hi = Math.max(plan.hi, ...angle) + 5;
  const X = (t) => top.x + ((t - t0) / (t1 - t0)) * top.w, Y = (v) => top.y + (1 - (v - lo) / (hi - lo)) * top.h;
  g.fillStyle = C.bad;
  for (let k = 0; k + 1 < time.length; k++) if (notHeld[k]) g.fillRect(X(time[k]), top.y, Math.max(1, X(time[k + 1]) - X(time[k])), top.h);
  g.strokeStyle = C.grid; g.strokeRect(top.x, top.y, top.w, top.h);
  g.fillStyle = C.dim;
  for (const v of [plan.lo, plan.hi]) g.fillText(`${v.toFixed(0)}°`, 8, Y(v) + 4);
  g.fillText(`${(t1 - t0).toFixed(1)} s`, top.x + top.w - 30, top.y + top.h + 14);
  const line = (values, colour, dash) => {
    g.strokeStyle = colour; g.lineWidth = 1.6; g.setLineDash(dash); g.beginPath();
    values.forEach((v, k) => (k ? g.lineTo(X(time[k]), Y(v)) : g.moveTo(X(time[k]), Y(v))));
    g.stroke(); g.setLineDash([]);
  };
  line(target, C.target, [5, 4]);
  line(angle, C.user, []);
  g.fillStyle = C.fg;
  reps.forEach((r, i) => {
    g.strokeStyle = C.grid; g.beginPath(); g.moveTo(X(r.startS), top.y); g.lineTo(X(r.startS), top.y + top.h); g.stroke();
    g.fillText(String(i + 1), X(r.startS + r.duration / 2) - 3, top.y + 12);
  });
  g.fillStyle = C.dim; g.fillText('target - - -   you —   red: the muscles could not hold', top.x + 6, top.y + top.h + 14);
  // bottom: per repetition
  const by = top.y + top.h + 34, bh = h - by - 44, n = Math.max(reps.length, 1), cw = (w - 60) / n;
  const maxEffort = Math.max(1, ...reps.map((r) => r.peakEffort));
  reps.forEach((r, i) => {
    const x = 46 + i * cw, mid = x + cw / 2;
    // range reached (bar) against the target's range (outline), on the angle scale
    const A = (v) => by + (1 - (v - lo) / (hi - lo)) * bh;
    g.strokeStyle = C.target; g.setLineDash([3, 3]); g.strokeRect(mid - cw * 0.34, A(plan.hi), cw * 0.18, A(plan.lo) - A(plan.hi)); g.setLineDash([]);
    g.fillStyle = C.user; g.fillRect(mid - cw * 0.34, A(r.highDeg), cw * 0.18, Math.max(1, A(r.lowDeg) - A(r.highDeg)));
    // effort: peak and mean
    const E = (v) => by + bh - (v / maxEffort) * bh;
    g.fillStyle = C.peak; g.fillRect(mid - cw * 0.08, E(r.peakEffort), cw * 0.16, by + bh - E(r.peakEffort));
    g.fillStyle = C.mean; g.fillRect(mid + cw * 0.1, E(r.meanEffort), cw * 0.16, by + bh - E(r.meanEffort));
    g.fillStyle = C.dim;
    for (const [label, at] of [['range', mid - cw * 0.25], ['peak', mid], ['mean', mid + cw * 0.18]]) {
      g.fillText(label, at - g.measureText(label).width / 2, by + bh + 11);
    }
    g.fillStyle = C.fg;
    g.fillText(`rep ${i + 1}: ${r.lowDeg.toFixed(0)}–${r.highDeg.toFixed(0)}°, ${r.duration.toFixed(1)} s`, x + 4, by + bh + 25);
    g.fillStyle = r.framesNotHeld ? '#ff9a7a' : C.dim;
    g.fillText(`effort peak ${r.peakEffort.toFixed(2)}, mean ${r.meanEffort.toFixed(2)}; not held ${r.framesNotHeld}`, x + 4, by + bh + 38);
  });
  if (!reps.length) { g.fillStyle = C.dim; g.fillText('no complete repetition (up by more than the hysteresis and back)', 50, by + bh / 2); }
  g.fillStyle = C.dim;
  g.fillText(`blue: range reached (dashed: target); red: peak effort, yellow: mean effort (sum of activations, scale 0–${maxEffort.toFixed(1)})`, 46, by - 8);
  if (file) g.fillText(file, w - 10 - g.measureText(file).width, 20);
}

// The repetitions as table rows (the panel's list).
export function repRows(reps) {
  return reps.map((r, i) => `<tr><td>${i + 1}</td><td>${r.lowDeg.toFixed(0)}–${r.highDeg.toFixed(0)}°</td>` +
    `<td>${r.duration.toFixed(1)} s</td><td>${r.peakEffort.toFixed(2)}</td><td>${r.meanEffort.toFixed(2)}</td>` +
    `<td${r.framesNotHeld ? ' class="bad"' : ''}>${r.framesNotHeld}</td></tr>`).join('');
}
