// Live input: a source's elbow samples (webcam or tracker) filtered (One Euro, velocity and
// acceleration from the smoothed angle), clamped to the reachable range (counted, as `persival
// motion play` counts them: velocity and acceleration stay the unclamped ones), and handed to the
// viewer, which runs them through the motion model and draws them. One message line says what
// is wrong, if anything; the arm holds its last valid state meanwhile. Per drawn sample the
// latency from its arrival in the page (a camera frame grabbed, a tracker message received) to
// the frame that shows it.
import { MotionFilter, FILTERS } from './one_euro.js';

export const PLAUSIBLE_DEG = [-30, 200]; // outside: not an elbow, a tracker error
const KEEP_PROBLEM_MS = 1500; // a problem stays on screen this long after it last happened
const RESTART_S = 0.5;

export class LiveInput {
  constructor(viewer, note) {
    this.v = viewer;
    this.note = note; // (text, isProblem) -> shows the one message line
    this.source = null; // 'webcam' | 'tracker'
    this.sample = null; // the newest valid sample: {seq, angle, target, velocity, acceleration, clamped, arrived, t}
    this.seq = 0;
    this.log = []; // drawn samples, for the latency figures and the tests (bounded)
    this.problemAt = -Infinity;
    this.listeners = new Set();
    this.resetCounts();
  }

  resetCounts() { this.counts = { samples: 0, clamped: 0, implausible: 0 }; this.latencies = []; }

  begin(source) {
    this.source = source;
    this.filter = new MotionFilter(FILTERS[source]);
    this.sample = null;
    this.resetCounts();
    this.log = [];
  }

  end() { this.source = null; this.sample = null; }

  get active() { return this.source !== null && this.sample !== null; }

  problem(text) {
    this.problemAt = performance.now();
    this.note(text, true);
  }

  // {angle (deg), t (s, the source's clock), arrived (performance.now ms)}
  push({ angle, t, arrived }) {
    if (!this.source) return;
    if (!(Number.isFinite(angle) && angle >= PLAUSIBLE_DEG[0] && angle <= PLAUSIBLE_DEG[1])) {
      this.counts.implausible++;
      this.problem(`the ${this.source} gives an elbow angle of ${Number(angle).toFixed(1)}°, not a possible one; the arm holds its last valid state`);
      return;
    }
    const time = Number.isFinite(t) ? t : arrived / 1000;
    // a time far behind the last: another clock (a tracker reconnected, another one): start afresh;
    // a little behind or repeated: out of order, ignored
    const restart = Boolean(this.sample) && time < this.sample.t - RESTART_S;
    if (restart) this.filter.reset();
    else if (this.sample && !(time > this.sample.t)) return;
    const m = this.filter.push(angle, time);
    const [lo, hi] = this.v.range;
    const clamped = m.angle < lo || m.angle > hi;
    if (clamped) this.counts.clamped++;
    this.counts.samples++;
    this.sample = { seq: ++this.seq, measured: angle, angle: m.angle, target: Math.min(hi, Math.max(lo, m.angle)),
      velocity: m.velocity, acceleration: m.acceleration, clamped, arrived, t: time, restart, load: this.v.state.load };
    for (const f of this.listeners) f(this.sample);
    if (performance.now() - this.problemAt > KEEP_PROBLEM_MS) {
      this.note(`${this.source === 'webcam' ? 'camera' : 'tracker'}: elbow ${m.angle.toFixed(0)}°` +
        (clamped ? ` (outside the model's ${lo.toFixed(0)}-${hi.toFixed(0)}°: drawn at ${this.sample.target.toFixed(0)}°)` : ''), false);
    }
    this.v.touch();
  }

  // The viewer drew the state of `sample` in the frame that ended at `now` (performance.now).
  drawn(sample, achieved, now) {
    const ms = now - sample.arrived;
    this.latencies.push(ms);
    if (this.latencies.length > 600) this.latencies.shift();
    this.log.push({ seq: sample.seq, t: sample.t, measured: sample.measured, angle: sample.angle, target: sample.target,
      achieved, arrived: sample.arrived, drawnAt: now, wallDrawn: performance.timeOrigin + now });
    if (this.log.length > 20000) this.log.shift();
  }

  // Median and 95th percentile of the input-to-frame latency over the last samples drawn (ms).
  latency() {
    const s = [...this.latencies].sort((a, b) => a - b);
    if (!s.length) return null;
    const q = (p) => s[Math.min(s.length - 1, Math.floor(p * (s.length - 1) + 0.5))];
    return { median: q(0.5), p95: q(0.95), n: s.length };
  }
}
