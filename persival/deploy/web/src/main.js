// The viewer: loads the export (metadata + ONNX), runs one state per frame where the automatic
// mode (or the user) says, writes it into the scene's preallocated buffers, and exposes the test
// hook window.persival.
import { ArmScene } from './scene.js';
import { LocalEngine, ServerEngine, configureOrt } from './inference.js';
import { calibrate, choose, Monitor, INFERENCE_BUDGET_MS } from './auto.js';
import { niceCeil } from './colormap.js';
import { setupControls } from './controls.js';
import * as ui from './ui.js';

const PLAY_PERIOD_S = 4;
const PLAY_SAMPLES = 240;

class Viewer {
  async start() {
    configureOrt();
    const r = await fetch('artifacts/metadata.json');
    if (!r.ok) throw new Error(`artifacts/metadata.json: HTTP ${r.status}`);
    this.meta = await r.json();
    this.local = new LocalEngine(this.meta);
    this.server = new ServerEngine(this.meta.n_nodes);
    this.scene = new ArmScene(document.getElementById('view'), this.meta);
    // The angle controls need the activation model; without it only the sliders drive the arm.
    this.hasAngleModel = Boolean(this.meta.models.activation_angle);
    this.range = this.meta.models.activation_angle?.range_deg ?? this.meta.elbow_angle_range_deg ?? [0, 140];
    this.hasMotion = Boolean(this.meta.models.activation_motion);
    this.tiers = Object.keys(this.meta.models.deformation.variants);
    this.state = { activations: new Float32Array(5), driver: 'activations', angle: this.range[0], load: 0 };
    this.serial = 0; this.applied = 0; this.waiters = [];
    this.mode = 'auto'; this.place = 'wasm'; this.tier = 'float32';
    this.playActivations = new Float32Array(5);
    this.frames = []; this.fps = 0; this.inferenceMs = NaN; this.states = 0; this.monitor = new Monitor();
    await this.scaleLegend();
    this.controls = setupControls(this);
    await this.runAuto();
    this.touch();
    this.scene.renderer.setAnimationLoop((t) => this.tick(t));
    await this.rendered();
    ui.status('');
  }

  async scaleLegend() {
    // The colour scale is fixed once from the extreme states (rest, all on, each muscle alone), so
    // a colour means the same displacement in every frame.
    const rows = [[0, 0, 0, 0, 0], [1, 1, 1, 1, 1], ...[0, 1, 2, 3, 4].map((i) => [0, 1, 2, 3, 4].map((j) => +(i === j)))];
    const p = await this.local.deformBatch(rows.flat());
    const X = this.scene.buffers.reference;
    const d = new Float32Array(rows.length * (X.length / 3));
    for (let s = 0, i = 0; s < rows.length; s++) {
      const off = s * X.length;
      for (let j = 0; j < X.length; j += 3, i++) d[i] = Math.hypot(p[off + j] - X[j], p[off + j + 1] - X[j + 1], p[off + j + 2] - X[j + 2]);
    }
    // The 98th percentile, not the maximum: a few far-travelling forearm nodes would otherwise
    // squeeze every other muscle into the bottom of the scale (they saturate instead).
    d.sort();
    const max = d[Math.floor(0.98 * (d.length - 1))];
    this.scene.buffers.scaleMm = niceCeil(max);
    ui.drawLegend(this.scene.buffers.scaleMm);
  }

  async runAuto() {
    let server = this.server;
    try { await server.connect(); } catch { server = null; }
    this.measured = await calibrate({ wasm: this.local, server }, this.tiers, new Float32Array(5).fill(0.5));
    this.pickAuto();
  }

  pickAuto(exclude = null) {
    const pool = this.measured.filter((m) => !exclude || m.place !== exclude.place || m.tier !== exclude.tier);
    const best = choose(pool.length ? pool : this.measured);
    this.place = best.place; this.tier = best.tier;
    this.monitor.reset();
    const list = this.measured.map((m) => `${m.place === 'wasm' ? 'browser' : 'server'} ${m.tier} ${m.ms.toFixed(2)}`);
    document.getElementById('decision').textContent =
      `auto picked ${best.place === 'wasm' ? 'browser' : 'server'} ${best.tier} (budget ${INFERENCE_BUDGET_MS.toFixed(1)} ms; ms: ${list.join(', ')})`;
    this.controls?.sync();
  }

  setMode(mode, tier) {
    this.mode = mode;
    if (mode === 'auto') this.pickAuto();
    else { this.place = mode; if (tier) this.tier = tier; }
    this.controls.sync();
    this.touch();
  }

  touch() { this.serial++; }

  rendered() {
    return new Promise((resolve, reject) => this.waiters.push({ serial: this.serial, resolve, reject }));
  }

  setActivations(a) {
    if (a.length !== 5 || !a.every((v) => Number.isFinite(v) && v >= 0 && v <= 1)) throw new Error('activations: five numbers in [0, 1]');
    this.state.activations.set(a);
    this.state.driver = 'activations';
    this.touch();
    return this.rendered();
  }

  setAngle(deg, load = this.state.load) {
    if (!this.hasAngleModel) throw new Error('this export has no activation model (activation_angle.onnx)');
    if (!(deg >= this.range[0] && deg <= this.range[1])) throw new Error(`angle outside [${this.range}]`);
    Object.assign(this.state, { angle: deg, load, driver: 'angle' });
    this.touch();
    return this.rendered();
  }

  // The play cycle's activations, tabulated once per load in one batched run: per frame only the
  // deformation model runs (one inference per frame, whatever the number of muscles).
  async playTable() {
    if (this.table?.load === this.state.load) return this.table;
    const n = PLAY_SAMPLES, w = (2 * Math.PI) / PLAY_PERIOD_S, amp = (this.range[1] - this.range[0]) / 2;
    const rows = [];
    for (let k = 0; k < n; k++) {
      const p = (w * k * PLAY_PERIOD_S) / n;
      rows.push([this.range[0] + amp * (1 - Math.cos(p)), amp * w * Math.sin(p), amp * w * w * Math.cos(p), this.state.load]);
    }
    const a = this.hasMotion ? await this.local.motionBatch(rows) : await this.local.angleBatch(rows.map((r) => r[0]));
    this.table = { load: this.state.load, angles: rows.map((r) => r[0]), a };
    return this.table;
  }

  async activationsForState() {
    const s = this.state;
    if (this.playing) {
      const t = await this.playTable();
      const u = ((((performance.now() - this.playStart) / 1000) % PLAY_PERIOD_S) / PLAY_PERIOD_S) * PLAY_SAMPLES;
      const k = Math.floor(u) % PLAY_SAMPLES, k1 = (k + 1) % PLAY_SAMPLES, f = u - Math.floor(u);
      const out = this.playActivations;
      for (let j = 0; j < 5; j++) out[j] = t.a[5 * k + j] * (1 - f) + t.a[5 * k1 + j] * f;
      s.angle = t.angles[k] * (1 - f) + t.angles[k1] * f;
      return out;
    }
    if (s.driver === 'angle') {
      return this.hasMotion && s.load > 0 ? this.local.activationsForMotion(s.angle, 0, 0, s.load) : this.local.activationsForAngle(s.angle);
    }
    return s.activations;
  }

  async infer() {
    const serial = this.serial;
    const a = await this.activationsForState();
    const t0 = performance.now();
    const r = await (this.place === 'wasm' ? this.local : this.server).deform(a, this.tier);
    const ms = performance.now() - t0;
    this.inferenceMs = Number.isFinite(this.inferenceMs) ? 0.8 * this.inferenceMs + 0.2 * ms : ms;
    this.state.activations.set(r.activations);
    this.scene.setPositions(r.positions);
    const angle = Number.isFinite(r.angle) ? r.angle : 0; // NaN: the export has no angle output
    this.scene.setElbowAngle(angle);
    this.elbowAngle = angle;
    this.states++;
    this.applied = serial;
    this.controls.show(r.activations, angle);
    if (this.mode === 'auto' && this.monitor.add(ms)) {
      const m = this.measured.find((x) => x.place === this.place && x.tier === this.tier);
      if (m) m.ms = this.monitor.ema;
      this.pickAuto(m);
    }
  }

  tick(now) {
    this.frames.push(now);
    while (this.frames.length && now - this.frames[0] > 1000) this.frames.shift();
    if (this.frames.length > 1) this.fps = ((this.frames.length - 1) * 1000) / (now - this.frames[0]);
    if (this.playing) this.touch();
    if (!this.busy && this.applied < this.serial) {
      this.busy = true;
      this.infer().catch((e) => { ui.status(String(e.message || e), true); this.fail(e); })
        .finally(() => { this.busy = false; });
    }
    this.scene.render();
    this.waiters = this.waiters.filter((w) => (this.applied >= w.serial && !this.busy ? (w.resolve(), false) : true));
    if ((this.hudAt || 0) < now - 250) { this.hudAt = now; this.hud(this.stats()); }
    if ((this.scaleAt || 0) < now - 500 && this.frames.length > 10) { this.scaleAt = now; this.scene.adaptResolution(this.fps); }
  }

  fail(e) {
    this.applied = this.serial; // do not retry the failed state every frame
    for (const w of this.waiters) w.reject(e);
    this.waiters = [];
  }

  stats() {
    return { fps: this.fps, inferenceMs: this.inferenceMs, backend: this.place, tier: this.tier, mode: this.mode,
      states: this.states, renderScale: this.scene.renderScale, elbowAngle: this.elbowAngle, playing: Boolean(this.playing) };
  }
}

const viewer = new Viewer();
viewer.hud = ui.hud();
const ready = viewer.start().catch((e) => { ui.status(`could not start: ${e.message || e}`, true); throw e; });

window.persival = {
  ready,
  viewer,
  async predict(a) { return Float32Array.from((await viewer.local.deform(Float32Array.from(a), 'float32')).positions); },
  async predictServer(a) { return Float32Array.from((await viewer.server.deform(Float32Array.from(a), 'float32')).positions); },
  setActivations: (a) => viewer.setActivations(a),
  setAngle: (deg, load) => viewer.setAngle(deg, load),
  setBackend: (mode, tier) => { viewer.setMode(mode, tier); return viewer.rendered(); },
  play: (on) => viewer.controls.play(on),
  stats: () => viewer.stats(),
};
