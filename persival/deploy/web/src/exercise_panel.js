// The panel's "Exercise" section: the target movement (range, tempo, repetitions, load), the
// ghost arm following it, live feedback per repetition, and at the end the summary: the exercise
// read back from its own CSV exactly as `persival motion play` reads it (player.analyse), the
// repetitions found in it, the summary picture, the CSV and the picture to save.
import { Exercise, findRepetitions } from './exercise.js';
import { drawSummary, repRows } from './exercise_view.js';

const hysteresis = (plan) => Math.max(5, 0.2 * (plan.hi - plan.lo));

export function setupExercise(v) {
  const $ = (id) => document.getElementById(id);
  const note = (text, bad = false) => { $('ex-note').textContent = text; $('ex-note').classList.toggle('refused', bad); };
  const [lo, hi] = v.range;
  $('ex-lo').value = String(Math.ceil(Math.max(lo, 20))); $('ex-hi').value = String(Math.floor(Math.min(hi, 120)));
  let ex = null, drawn = null, shownAt = 0, urls = [];

  function plan() {
    const p = { lo: Number($('ex-lo').value), hi: Number($('ex-hi').value), period: Number($('ex-period').value),
      reps: Math.round(Number($('ex-reps').value)), load: Number($('ex-load').value) };
    if (!Object.values(p).every(Number.isFinite)) return { error: 'every field of the exercise needs a number' };
    if (!(p.lo >= lo - 1e-9 && p.hi <= hi + 1e-9 && p.hi - p.lo >= 10)) {
      return { error: `the range must lie in the model's ${lo.toFixed(0)}-${hi.toFixed(0)}° and span 10° or more` };
    }
    if (!(p.period >= 1 && p.period <= 60 && p.reps >= 1 && p.reps <= 50)) return { error: '1 to 60 s per repetition, 1 to 50 repetitions' };
    let held = Infinity;
    for (let a = p.lo; a <= p.hi; a += 1) held = Math.min(held, v.held(a));
    held = Math.min(held, v.held(p.hi));
    if (!(p.load >= 0) || p.load > held + 1e-9) {
      return { error: `${p.load.toFixed(1)} kg cannot be held over ${p.lo.toFixed(0)}-${p.hi.toFixed(0)}°: the muscles hold at most ${Math.max(held, 0).toFixed(2)} kg there` };
    }
    return { plan: p };
  }

  function start() {
    if (ex) { finish(); return { ok: true, stopped: true }; }
    const r = plan();
    if (r.error) { note(r.error, true); return { ok: false, message: r.error }; }
    if (!v.liveOn) { const m = 'switch on the webcam or the tracker first: the exercise follows your own elbow'; note(m, true); return { ok: false, message: m }; }
    v.setLiveLoad(r.plan.load);
    ex = new Exercise(r.plan);
    drawn = { time: [], angle: [], effort: [], notHeld: [] };
    ex.start(performance.now());
    $('ex-start').innerHTML = '&#9632; stop exercise';
    $('ex-summary').hidden = true; $('ex-files').hidden = true; $('ex-table').hidden = true;
    note(`follow the ghost arm: ${r.plan.reps} × ${r.plan.lo}-${r.plan.hi}°, ${r.plan.period} s each`);
    return { ok: true, plan: r.plan };
  }

  async function finish() {
    const done = ex;
    ex = null;
    v.ghost.set(null);
    $('ex-start').innerHTML = '&#9654; start exercise (follow the ghost arm)';
    if (!done) return null;
    const csv = done.csv(), live = liveReps(done);
    if (done.rows.length < 2) { note('no elbow samples were recorded: nothing to save', true); v.exerciseResult = { ok: false, csv }; return null; }
    try {
      // the same reading as `persival motion play`: its CSV, resampled and smoothed, then the models
      const rec = await v.player.analyse(csv, 'exercise.csv');
      const n = rec.time.length, effortSum = Array.from({ length: n }, (_, k) => rec.effort.subarray(5 * k, 5 * k + 5).reduce((a, b) => a + b, 0));
      const reps = findRepetitions(rec.time, rec.target, effortSum, rec.notHeld, hysteresis(done.plan));
      const target = Array.from(rec.time, (t) => targetAt(done, t));
      drawSummary($('ex-picture'), { plan: done.plan, time: rec.time, angle: rec.target, target, notHeld: rec.notHeld, reps,
        framesClamped: rec.framesClamped });
      $('ex-summary').hidden = false;
      $('ex-table').querySelector('tbody').innerHTML = repRows(reps);
      $('ex-table').hidden = false;
      for (const u of urls) URL.revokeObjectURL(u);
      urls = [URL.createObjectURL(new Blob([csv], { type: 'text/csv' }))];
      $('ex-csv').href = urls[0];
      $('ex-picture').toBlob((b) => { if (b) { urls.push(URL.createObjectURL(b)); $('ex-png').href = urls[1]; } });
      $('ex-files').hidden = false;
      note(`done: ${reps.length} repetition${reps.length === 1 ? '' : 's'}; ${rec.framesClamped} frames clamped, ${rec.framesNotHeld} the muscles could not hold`);
      v.exerciseResult = { ok: true, csv, reps, liveReps: live, plan: done.plan, frames: n, framesClamped: rec.framesClamped,
        framesNotHeld: rec.framesNotHeld, activations: Array.from(rec.effort), time: Array.from(rec.time), target: Array.from(rec.target) };
    } catch (e) {
      note(String(e.message || e), true);
      v.exerciseResult = { ok: false, csv, message: String(e.message || e) };
    }
    return v.exerciseResult;
  }

  const targetAt = (e, t) => e.target(e.t0 + 1000 * t);

  function liveReps(e) {
    return findRepetitions(drawn.time, drawn.angle, drawn.effort, drawn.notHeld, hysteresis(e.plan));
  }

  v.live.listeners.add((s) => ex?.record(s));
  $('ex-start').addEventListener('click', () => start());
  $('ex-close').addEventListener('click', () => { $('ex-summary').hidden = true; });

  return {
    start,
    finish,
    running: () => ex !== null,
    // every frame: the ghost at the target; after the end, the summary
    tick(now) {
      if (!ex) return;
      v.ghost.set(ex.target(now));
      if (ex.done(now)) { finish(); return; }
      if (now - shownAt > 250) {
        shownAt = now;
        const reps = liveReps(ex), last = reps[reps.length - 1];
        const t = ex.elapsed(now), rep = Math.min(ex.plan.reps, Math.floor(t / ex.plan.period) + 1);
        note(`repetition ${rep} of ${ex.plan.reps} (target ${ex.target(now).toFixed(0)}°)` + (last ? `; last: ${last.lowDeg.toFixed(0)}-${last.highDeg.toFixed(0)}°, ` +
          `${last.duration.toFixed(1)} s, effort peak ${last.peakEffort.toFixed(2)} mean ${last.meanEffort.toFixed(2)}, not held ${last.framesNotHeld}` : ''));
      }
    },
    target: (now) => (ex ? ex.target(now) : null),
    // a live state drawn: its effort for the live feedback
    drawn(sample, effort, notHeld) {
      if (!ex) return;
      drawn.time.push((sample.arrived - ex.t0) / 1000); drawn.angle.push(sample.angle);
      drawn.effort.push(effort.reduce((a, b) => a + b, 0)); drawn.notHeld.push(notHeld);
    },
  };
}
