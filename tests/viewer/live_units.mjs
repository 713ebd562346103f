// The live modules' arithmetic in Node (no browser): the One Euro filter and the velocity and
// acceleration from it, the elbow angle from joint positions and from segment orientations, the
// tracker message reader, the repetition finder and the exercise's CSV as the recording reader
// takes it. Prints one JSON object; tests/deploy/test_live_units.py judges it.
import { OneEuroFilter, MotionFilter, FILTERS } from '../../persival/deploy/web/src/live/one_euro.js';
import { flexionFromPoints, flexionFromQuaternions, unitQuaternion } from '../../persival/deploy/web/src/live/geometry.js';
import { readMessage } from '../../persival/deploy/web/src/live/tracker_socket.js';
import { Exercise, findRepetitions, targetAngle } from '../../persival/deploy/web/src/exercise.js';
import { parseRecording } from '../../persival/deploy/web/src/recording.js';

const out = {};
let seed = 7;
const noise = () => ((seed = (seed * 16807) % 2147483647) / 2147483647 - 0.5); // uniform in [-0.5, 0.5)

// One Euro: a constant stays, a step is approached without overshoot
{
  const f = new OneEuroFilter({ minCutoff: 1, beta: 0.05 });
  const constant = Array.from({ length: 50 }, (_, k) => f.filter(42, k / 30));
  const g = new OneEuroFilter({ minCutoff: 1, beta: 0.05 });
  const step = Array.from({ length: 90 }, (_, k) => g.filter(k < 10 ? 0 : 100, k / 30));
  out.constant = Math.max(...constant.map((v) => Math.abs(v - 42)));
  out.stepMax = Math.max(...step);
  out.stepMonotone = step.every((v, k) => k === 0 || v >= step[k - 1] - 1e-12);
  out.stepFinal = step[step.length - 1];
}
// the tracker's filter on the test movement (0-120-0 deg in 2 s, 60 Hz) and on a still arm with noise
for (const [name, params] of Object.entries(FILTERS)) {
  const f = new MotionFilter(params);
  let lag = 0, vErr = 0, aPeak = 0;
  for (let k = 0; k <= 120; k++) {
    const t = k / 60, a = 60 * (1 - Math.cos(Math.PI * t)), r = f.push(a, t);
    if (a >= 10 && a <= 120) lag = Math.max(lag, Math.abs(r.angle - a));
    if (k > 20) vErr = Math.max(vErr, Math.abs(r.velocity - 60 * Math.PI * Math.sin(Math.PI * t)));
    aPeak = Math.max(aPeak, Math.abs(r.acceleration));
  }
  const s = new MotionFilter(params);
  let sq = 0, n = 0;
  for (let k = 0; k < 600; k++) { const r = s.push(60 + 2 * noise(), k / 60); if (k > 60) { sq += (r.angle - 60) ** 2; n++; } }
  out[`filter_${name}`] = { lagDeg: lag, velocityErr: vErr, accelerationPeak: aPeak, accelerationTrue: 60 * Math.PI ** 2,
    stillRmsDeg: Math.sqrt(sq / n), inputRmsDeg: 2 / Math.sqrt(12) };
}
// geometry
out.straight = flexionFromPoints({ x: 0, y: 0, z: 0 }, { x: 0, y: -1, z: 0 }, { x: 0, y: -2, z: 0 });
out.rightAngle = flexionFromPoints([0, 0, 0], [0, -1, 0], [0, -1, 1]);
out.degenerate = flexionFromPoints([0, 0, 0], [0, 0, 0], [1, 0, 0]);
const q = (axis, deg) => { const h = (deg * Math.PI) / 360; return [Math.cos(h), ...axis.map((v) => v * Math.sin(h))]; };
const mul = (a, b) => [a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3], a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
  a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1], a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]];
out.quaternions = [0, 30, 90, 135].map((deg) => {
  const upper = mul(q([0, 0, 1], 25), q([0, 1, 0], 90)); // any upper-arm orientation
  return [0, 45, -70].map((twist) => flexionFromQuaternions(upper, mul(mul(upper, q([0, 1, 0], -deg)), q([1, 0, 0], twist))) - deg);
}).flat();
out.unit = [unitQuaternion([2, 0, 0, 0]), unitQuaternion([1, 0, 0]), unitQuaternion([0.99, 0, 0, 0]), unitQuaternion([1, NaN, 0, 0])];
// the tracker's messages
out.messages = Object.fromEntries([
  ['angle', '{"t": 12.5, "elbow_deg": 87.5}'], ['quaternions', JSON.stringify({ upper_arm: [1, 0, 0, 0], forearm: q([0, 1, 0], 60) })],
  ['axis', JSON.stringify({ upper_arm: [1, 0, 0, 0], forearm: q([1, 0, 0], 60), axis: [0, 0, 1] })],
  ['notJson', 'elbow 87'], ['array', '[87]'], ['string', '{"elbow_deg": "87"}'], ['nan', '{"elbow_deg": NaN}'],
  ['badTime', '{"t": "now", "elbow_deg": 80}'], ['notUnit', '{"upper_arm": [3, 0, 0, 0], "forearm": [1, 0, 0, 0]}'],
  ['badAxis', '{"upper_arm": [1, 0, 0, 0], "forearm": [1, 0, 0, 0], "axis": [0, 0, 0]}'], ['neither', '{"knee_deg": 10}'],
  ['status', '{"type": "status", "publishers": 1}'], ['relayError', '{"error": "slow down", "status": 429}'],
].map(([k, text]) => [k, readMessage(text)]));
// repetitions: three curls with noise, a rest; wobbles below the hysteresis
{
  const plan = { lo: 20, hi: 110, period: 3, reps: 3 };
  const time = [], angle = [], effort = [], held = [];
  for (let k = 0; k <= 30 * 11; k++) {
    const t = k / 30;
    time.push(t);
    angle.push((t < 9.5 ? targetAngle(plan, t - 0.5) : 20) + noise());
    effort.push(0.2 + angle[k] / 200); held.push(t > 4 && t < 4.2);
  }
  const reps = findRepetitions(time, angle, effort, held, Math.max(5, 0.2 * (plan.hi - plan.lo)));
  out.reps = reps.map((r) => ({ duration: r.duration, low: r.lowDeg, high: r.highDeg, peak: r.peakEffort, mean: r.meanEffort, notHeld: r.framesNotHeld }));
  const wobble = time.map((t) => 60 + 6 * Math.sin(8 * t) + noise()); // small movements: below the hysteresis
  out.noReps = findRepetitions(time, wobble, effort, held, 18).length;
}
// the exercise's CSV, read by the recording reader (`persival motion play` reads it the same way)
{
  const ex = new Exercise({ lo: 20, hi: 100, period: 2, reps: 1, load: 1.5 });
  ex.start(1000);
  for (let k = 0; k < 10; k++) ex.record({ arrived: 1000 + 100 + k * 16.7, t: 500 + k / 60, angle: 20 + k, measured: 20.5 + k });
  ex.record({ arrived: 1300, t: 500 + 9 / 60, angle: 99, measured: 99 }); // a repeated time: dropped
  const parsed = parseRecording(ex.csv(), 'exercise.csv');
  out.csv = { header: ex.csv().split('\n')[0], column: parsed.column, time: parsed.time, angle: parsed.angle, load: parsed.load };
}
console.log(JSON.stringify(out));
