// An exercise to follow: a target movement (a range, a tempo in seconds per repetition, a number
// of repetitions, a load), the target angle over time (what the ghost arm shows), the samples of
// the user's elbow recorded against it, repetitions found in the user's own movement, and the
// exercise written as a CSV that `persival motion play` reads back (docs/viewer.md, "Live").

// The target: from the bottom of the range up and back, a cosine per repetition (at rest at both
// ends, as a therapist demonstrates a curl).
export function targetAngle({ lo, hi, period, reps }, t) {
  if (t <= 0) return lo;
  if (t >= reps * period) return lo;
  return lo + ((hi - lo) / 2) * (1 - Math.cos((2 * Math.PI * t) / period));
}

// Repetitions in a movement: valley -> peak -> valley, each turn confirmed once the angle has
// come back by `hysteresis` degrees (noise and small wobbles are no repetition). A repetition
// starts when the arm leaves the bottom (its last frame within a tenth of the hysteresis of the
// valley) and ends when it is back there (its first such frame): a rest in between, however
// noisy, is no part of it. Per repetition:
// its frames [start, end], duration, the lowest and highest angle reached, peak and mean effort
// (the sum of the five activations per frame) and the frames the muscles could not hold.
export function findRepetitions(time, angle, effort, notHeld, hysteresis) {
  const n = angle.length, valleys = [], peaks = [];
  if (n < 3) return [];
  let rising = false, ext = angle[0], at = 0;
  for (let k = 1; k < n; k++) {
    const a = angle[k];
    if (!rising) {
      if (a < ext) { ext = a; at = k; } else if (a > ext + hysteresis) { valleys.push(at); rising = true; ext = a; at = k; }
    } else if (a > ext) { ext = a; at = k; } else if (a < ext - hysteresis) { peaks.push(at); rising = false; ext = a; at = k; }
  }
  // back down at the end, though not up again: the last valley is the lowest point since the peak
  if (!rising && peaks.length && (!valleys.length || peaks[peaks.length - 1] > valleys[valleys.length - 1])) valleys.push(at);
  const reps = [];
  for (let i = 0; i + 1 < valleys.length; i++) {
    const [v0, v1] = [valleys[i], valleys[i + 1]];
    const peak = peaks.find((p) => p > v0 && p < v1);
    if (peak === undefined) continue;
    const tol = Math.max(1, hysteresis / 10);
    let s = peak, e = peak;
    while (s > v0 && angle[s] > angle[v0] + tol) s--;
    while (e < v1 && angle[e] > angle[v1] + tol) e++;
    let lo = Infinity, hi = -Infinity, sum = 0, max = 0, held = 0;
    for (let k = s; k <= e; k++) {
      lo = Math.min(lo, angle[k]); hi = Math.max(hi, angle[k]);
      sum += effort[k]; max = Math.max(max, effort[k]); held += notHeld[k] ? 1 : 0;
    }
    reps.push({ start: s, end: e, startS: time[s], duration: time[e] - time[s], lowDeg: lo, highDeg: hi, rangeDeg: hi - lo,
      peakEffort: max, meanEffort: sum / (e - s + 1), framesNotHeld: held, frames: e - s + 1 });
  }
  return reps;
}

export const HEADER = 'time_s,elbow_angle_deg,load_kg,target_deg,measured_deg';

export class Exercise {
  // plan: {lo, hi, period (s per repetition), reps, load (kg)}
  constructor(plan) {
    this.plan = plan;
    this.duration = plan.reps * plan.period;
    this.rows = [];
    this.t0 = null; // performance.now at the start
  }

  start(now) { this.t0 = now; }

  elapsed(now) { return this.t0 === null ? 0 : (now - this.t0) / 1000; }

  target(now) { return targetAngle(this.plan, this.elapsed(now)); }

  done(now) { return this.elapsed(now) > this.duration + 0.5; } // half a second for the last return

  // A live sample (its filtered, unclamped angle and the raw measurement) at the source's own time
  // (a tracker's time stamps, a camera frame's): the page's arrival times jitter by milliseconds
  // when messages queue, which velocity and acceleration would turn into spikes. The first sample
  // ties the source's clock to the exercise's (its arrival), and so does a restarted source.
  record(sample) {
    if (this.clock === undefined || sample.restart) { // the first sample, or a source with another clock
      if (sample.arrived < this.t0) return;
      this.clock = (sample.arrived - this.t0) / 1000 - sample.t;
    }
    const t = sample.t + this.clock;
    if (t < 0) return;
    const last = this.rows[this.rows.length - 1];
    if (last && !(t > last[0] + 1e-4)) return; // the CSV's time (0.1 ms) must increase
    this.rows.push([t, sample.angle, this.plan.load, targetAngle(this.plan, t), sample.measured]);
  }

  // The CSV: `persival motion play` takes the time, the elbow angle (the filtered one, as the arm
  // followed it) and the load column; the target and the raw measurement ride along.
  csv() {
    const f = (v, d) => v.toFixed(d);
    return `${HEADER}\n${this.rows.map((r) => [f(r[0], 4), f(r[1], 4), f(r[2], 3), f(r[3], 4), f(r[4], 4)].join(',')).join('\n')}\n`;
  }
}
