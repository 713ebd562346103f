// A recorded movement played at its own speed: the file is read and prepared as `persival motion
// play` does (recording.js), the motion-and-load model gives every frame's activations in one
// batched run, the angle model (or the static effort: main.js, drawnFor) the drawn arm's; each
// drawn frame records the achieved elbow angle and extends the live graphs.
import { parseRecording, prepareRecording, RATE_HZ } from './recording.js';

export class RecordingPlayer {
  constructor(viewer) {
    this.v = viewer;
    this.rec = null;
    this.playing = false;
    this.drawn = new Float32Array(5);
    this.effort = new Float32Array(5);
  }

  async open(text, name, column = null) {
    this.rec = await this.analyse(text, name, column);
    this.v.graphs.show(this.rec);
    this.v.scene.bottomInset = this.v.graphs.canvas.parentElement.offsetHeight;
    this.v.scene.resize();
    this.start();
    return this.summary();
  }

  // A movement read and prepared as `persival motion play` does, with every frame's activations
  // (effort and drawn), without playing it: what open() plays, and what an exercise's summary
  // reports.
  async analyse(text, name, column = null) {
    const v = this.v;
    if (!v.hasAngleModel) throw new Error('this export has no activation model (activation_angle.onnx): it cannot play a movement');
    const parsed = parseRecording(text, name, column);
    const rec = prepareRecording(parsed, v.range, parsed.load ? null : v.state.load);
    const n = rec.time.length;
    rec.drawn = await v.drawnFor(Array.from(rec.target), Array.from(rec.load));
    rec.effort = rec.drawn;
    let deficit = null;
    if (v.hasMotion) {
      const rows = Array.from({ length: n }, (_, k) => [rec.target[k], rec.velocity[k], rec.acceleration[k], rec.load[k]]);
      ({ activations: rec.effort, deficit } = await v.local.motionWithDeficit(rows));
    } else if (rec.load.some((x) => x > 0)) {
      throw new Error('a load needs the motion-and-load model, which this export does not have');
    }
    rec.effortOf = [0, 1, 2, 3, 4].map((m) => Float32Array.from({ length: n }, (_, k) => rec.effort[5 * k + m]));
    rec.notHeld = Array.from({ length: n }, (_, k) => Boolean(deficit && deficit[k] !== 0));
    rec.framesNotHeld = rec.notHeld.filter(Boolean).length;
    rec.achieved = new Float64Array(n).fill(NaN);
    Object.assign(rec, { range: v.range, file: name, column: parsed.column });
    return rec;
  }

  start() {
    this.playing = true;
    this.t0 = null; // set by the first frame drawn, so loading time is not playing time
    this.last = -1;
    this.maxError = 0;
    this.errors = 0;
    this.v.touch();
  }

  stop() { this.playing = false; }

  // The frame at this moment of the recording: drawn and effort activations interpolated between
  // the 100 Hz frames, and the index reached. Past the end: the last frame, and playing stops.
  frame(now) {
    const rec = this.rec, n = rec.time.length;
    if (this.t0 === null) this.t0 = now;
    let u = ((now - this.t0) / 1000) * RATE_HZ;
    if (u >= n - 1) { u = n - 1; this.playing = false; }
    const k = Math.min(Math.floor(u), n - 1), k1 = Math.min(k + 1, n - 1), f = u - k;
    for (let j = 0; j < 5; j++) {
      this.drawn[j] = rec.drawn[5 * k + j] * (1 - f) + rec.drawn[5 * k1 + j] * f;
      this.effort[j] = rec.effort[5 * k + j] * (1 - f) + rec.effort[5 * k1 + j] * f;
    }
    return { drawn: this.drawn, effort: this.effort, k, target: rec.target[k] * (1 - f) + rec.target[k1] * f,
      load: rec.load[k] * (1 - f) + rec.load[k1] * f };
  }

  // The drawn state of frame k reached `angle`: fill the achieved curve up to k (frames skipped
  // between two drawn ones are interpolated) and extend the graphs.
  record(k, angle, target) {
    const rec = this.rec;
    if (!rec || !Number.isFinite(angle)) return;
    const a = rec.achieved;
    const from = this.last >= 0 && this.last < k ? this.last : k;
    for (let i = from + 1; i < k; i++) a[i] = a[from] + ((angle - a[from]) * (i - from)) / (k - from);
    a[k] = angle;
    this.last = k;
    this.maxError = Math.max(this.maxError, Math.abs(angle - target));
    this.errors++;
    this.v.graphs.update(k);
    this.v.scene.refreshGraphPanel();
  }

  summary() {
    const rec = this.rec;
    if (!rec) return null;
    return { file: rec.file, column: rec.column, frames: rec.time.length, duration: rec.duration,
      framesClamped: rec.framesClamped, framesNotHeld: rec.framesNotHeld, playing: this.playing,
      played: this.last + 1, statesDrawn: this.errors, maxAngleErrorDeg: this.maxError,
      graphUpdates: this.v.graphs.updates, loadKg: [Math.min(...rec.load), Math.max(...rec.load)] };
  }
}
