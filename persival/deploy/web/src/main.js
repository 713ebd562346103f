// The viewer: loads the export (metadata + ONNX), runs one state per frame where the automatic
// mode (or the user) says, writes it into the scene's preallocated buffers, and exposes the test
// hook window.persival.
//
// Two sets of activations per state. The *effort* is what the muscles do: the motion-and-load
// model's activations for the angle, its velocity and acceleration and the load in the hand (the
// sliders, the activation colours and the graphs show it). The *drawn* state is the deformation
// model at its own least-effort activations for the same angle (activation_angle.onnx): the
// deformation model has no load input, and fed the loaded activations the unloaded arm would flex
// past the target (the 143-degree jump of a 2 kg load at 90 degrees). A deformation model that
// takes the load (`load_kg`: it solves the elbow's equilibrium with the load in the hand) is fed
// the static effort and the load instead, and draws the loaded arm; in the browser it runs from
// the export's `load_variant` (deformation_load.onnx, the load a required input: see inference.js).
// The drawn state's elbow angle is the "achieved" angle; a load the muscles cannot hold at an
// angle is refused.
//
// A live source (the user's own elbow from a webcam or a tracker: live/) drives the arm whenever
// it is on: each new sample's angle, velocity and acceleration and the load go through the motion
// model as a recording's frames do, the drawn state as setAngle's; an exercise (exercise.js) adds
// a ghost arm at its target and per-repetition feedback.
import { ArmScene } from './scene.js';
import { LocalEngine, ServerEngine, configureOrt } from './inference.js';
import { calibrate, choose, Monitor, INFERENCE_BUDGET_MS } from './auto.js';
import { niceCeil } from './colormap.js';
import { setupControls } from './controls.js';
import { Graphs } from './graphs.js';
import { Holdable, refusal } from './load.js';
import { RecordingPlayer } from './player.js';
import { GhostArm } from './ghost.js';
import { LiveInput } from './live/live_input.js';
import { LiveGraphs } from './live/live_graphs.js';
import { setupLive } from './live/live_panel.js';
import { setupExercise } from './exercise_panel.js';
import * as ui from './ui.js';

const PLAY_PERIOD_S = 4;
const PLAY_SAMPLES = 240;
const MIN_PLAY_SPAN_DEG = 5;

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
    this.hasMotion = Boolean(this.meta.models.activation_motion);
    // a deformation model with a load input the browser can feed (the export's load variant, or a
    // true input of deformation.onnx) draws the loaded arm itself (see drawnFor)
    this.loadInput = this.hasMotion && await this.local.loadInput();
    this.range = this.angleRange();
    this.tiers = Object.keys(this.meta.models.deformation.variants);
    this.state = { activations: new Float32Array(5), driver: 'activations', angle: this.range[0], load: 0 };
    this.effort = new Float32Array(5);
    this.serial = 0; this.applied = 0; this.waiters = [];
    this.mode = 'auto'; this.place = 'wasm'; this.tier = 'float32';
    this.playDrawn = new Float32Array(5); this.playEffort = new Float32Array(5);
    this.frames = []; this.fps = 0; this.inferenceMs = NaN; this.states = 0; this.monitor = new Monitor();
    this.resetProfile();
    this.holdable = this.hasMotion && this.hasAngleModel ? await Holdable.build(this.local, this.meta, this.range) : null;
    this.graphs = new Graphs(document.getElementById('graphs'), this.meta.muscles);
    this.player = new RecordingPlayer(this);
    this.live = new LiveInput(this, () => {});
    this.liveGraphs = new LiveGraphs(document.getElementById('graphs'), this.range);
    this.ghost = new GhostArm(this.scene);
    await this.scaleLegend();
    this.controls = setupControls(this);
    this.liveUi = setupLive(this);
    this.exerciseUi = setupExercise(this);
    await this.runAuto();
    this.touch();
    this.scene.renderer.setAnimationLoop((t) => this.tick(t));
    await this.rendered();
    ui.status('');
  }

  // Angles every model covers: the angle model's range within the motion model's.
  angleRange() {
    const models = this.meta.models;
    let [lo, hi] = models.activation_angle?.range_deg ?? this.meta.elbow_angle_range_deg ?? [0, 140];
    const motion = models.activation_motion?.range_deg;
    if (motion) { lo = Math.max(lo, motion[0]); hi = Math.min(hi, motion[1]); }
    return [lo, hi];
  }

  async scaleLegend() {
    // Colours measure the displacement from the hanging arm (all activations zero), as the FE
    // pictures do. The scale is fixed once from the extreme states (all on, each muscle alone), so
    // a colour means the same displacement in every frame.
    const rows = [[0, 0, 0, 0, 0], [1, 1, 1, 1, 1], ...[0, 1, 2, 3, 4].map((i) => [0, 1, 2, 3, 4].map((j) => +(i === j)))];
    const p = await this.local.deformBatch(rows.flat());
    const n3 = this.scene.buffers.reference.length;
    const X = Float32Array.from(p.subarray(0, n3)); // the hanging arm
    this.scene.buffers.reference = X;
    const d = new Float32Array((rows.length - 1) * (n3 / 3));
    for (let s = 1, i = 0; s < rows.length; s++) {
      const off = s * n3;
      for (let j = 0; j < n3; j += 3, i++) d[i] = Math.hypot(p[off + j] - X[j], p[off + j + 1] - X[j + 1], p[off + j + 2] - X[j + 2]);
    }
    // The 98th percentile, not the maximum: a few far-travelling forearm nodes would otherwise
    // squeeze every other muscle into the bottom of the scale (they saturate instead).
    d.sort();
    this.scene.buffers.scaleMm = niceCeil(d[Math.floor(0.98 * (d.length - 1))]);
    this.showLegend();
  }

  setColourMode(activation) {
    this.scene.buffers.activations = activation ? this.effort : null;
    document.getElementById('activation-colours').checked = Boolean(activation);
    this.showLegend();
    this.touch();
    return this.rendered();
  }

  showLegend() {
    if (this.scene.buffers.activations) ui.drawLegend(1, 'activation of each muscle (0 to 1)', 1);
    else ui.drawLegend(this.scene.buffers.scaleMm, 'displacement from the hanging arm (mm)');
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
    this.player.stop();
    this.state.activations.set(a);
    this.state.driver = 'activations';
    this.touch();
    return this.rendered();
  }

  // The heaviest load held at an angle (Infinity without the motion model's holding information).
  held(deg) { return this.holdable ? this.holdable.at(deg) : Infinity; }

  // {ok, message}: a load the muscles cannot hold at the angle is refused with the number they can.
  checkLoad(load, deg) {
    const held = this.held(deg);
    return load <= held + 1e-9 ? { ok: true, held } : { ok: false, held, message: refusal(load, deg, held) };
  }

  async setAngle(deg, load = this.state.load) {
    if (!this.hasAngleModel) throw new Error('this export has no activation model (activation_angle.onnx)');
    if (!(deg >= this.range[0] && deg <= this.range[1])) throw new Error(`angle outside [${this.range}]`);
    const check = this.checkLoad(load, deg);
    if (!check.ok) return check;
    this.player.stop();
    Object.assign(this.state, { angle: deg, load, driver: 'angle' });
    this.touch();
    await this.rendered();
    return check;
  }

  async setLoad(kg) {
    if (!this.hasMotion) return { ok: false, message: 'this export has no motion-and-load model: no load can be set' };
    const max = this.holdable?.maxLoad ?? this.meta.models.activation_motion.max_load_kg;
    if (!(kg >= 0 && kg <= max + 1e-9)) return { ok: false, message: `the load must lie in [0, ${max.toFixed(2)}] kg` };
    const check = this.playing ? this.playSpan(kg) : this.checkLoad(kg, this.state.angle);
    if (!check.ok) return check;
    this.state.load = kg;
    if (this.state.driver === 'angle' || this.playing) this.touch();
    await this.rendered();
    return check;
  }

  // The flexion-extension cycle for a load: the unbroken stretch of the range around the current
  // angle where the load is held (the whole range without a load), so play never pushes the arm
  // where the muscles give out.
  playSpan(load = this.state.load) {
    if (!this.holdable) return { ok: true, span: this.range };
    const span = this.holdable.interval(load, this.state.angle);
    if (!span || span[1] - span[0] < MIN_PLAY_SPAN_DEG) {
      const best = Math.max(...this.holdable.kg);
      return { ok: false, message: `${load.toFixed(1)} kg cannot be held over a flexion-extension cycle: the muscles ` +
        `hold at most ${best.toFixed(2)} kg anywhere in the range` };
    }
    return { ok: true, span: [Math.max(span[0], this.range[0]), Math.min(span[1], this.range[1])] };
  }

  // The play cycle's activations, tabulated once per load in batched runs: per frame only the
  // deformation model runs (one inference per frame, whatever the number of muscles).
  async playTable() {
    if (this.table?.load === this.state.load) return this.table;
    const check = this.playSpan();
    const [lo, hi] = check.ok ? check.span : this.range;
    const n = PLAY_SAMPLES, w = (2 * Math.PI) / PLAY_PERIOD_S, amp = (hi - lo) / 2;
    const rows = [];
    for (let k = 0; k < n; k++) {
      const p = (w * k * PLAY_PERIOD_S) / n;
      rows.push([lo + amp * (1 - Math.cos(p)), amp * w * Math.sin(p), amp * w * w * Math.cos(p), this.state.load]);
    }
    const angles = rows.map((r) => r[0]);
    const drawn = await this.drawnFor(angles, rows.map((r) => r[3]));
    const effort = this.hasMotion ? await this.local.motionBatch(rows) : drawn;
    this.table = { load: this.state.load, angles, drawn, effort, span: [lo, hi] };
    return this.table;
  }

  // The drawn states' activations for target angles (and loads): the angle model's, or with a
  // load-taking deformation model the static effort (zero velocity and acceleration) with the load.
  async drawnFor(angles, loads) {
    if (!this.loadInput) return this.local.angleBatch(angles);
    return this.local.motionBatch(angles.map((a, k) => [a, 0, 0, loads[k]]));
  }

  // A live source takes over the arm (live/live_panel.js calls these).
  startLive(source) {
    this.player.stop();
    if (this.playing) this.controls.play(false);
    this.graphs.hide();
    this.live.begin(source);
    this.liveOn = true;
    this.liveCache = null;
    this.liveGraphs.clear();
    this.liveGraphs.show();
    this.scene.bottomInset = this.liveGraphs.canvas.parentElement.offsetHeight;
    this.scene.resize();
  }

  stopLive() {
    if (!this.liveOn) return;
    if (this.exerciseUi?.running()) this.exerciseUi.finish();
    this.liveOn = false;
    this.live.end();
    this.state.driver = 'angle'; // the arm stays at the last live angle
    this.liveGraphs.hide();
    this.scene.bottomInset = 0;
    this.scene.resize();
    this.touch();
  }

  // The load in the hand while the user moves: checked by the caller over the whole movement (an
  // exercise's range), not at the current angle.
  setLiveLoad(kg) {
    this.state.load = kg;
    document.getElementById('load').value = String(kg);
    document.getElementById('load-out').value = `${kg.toFixed(1)} kg`;
    this.liveCache = null;
  }

  // The newest live sample's state: the motion model's effort (and whether the muscles hold it)
  // for its angle, velocity, acceleration and the load; the drawn arm's activations for its angle.
  async liveState() {
    const s = this.live.sample, load = this.state.load;
    if (this.liveCache?.seq !== s.seq || this.liveCache.load !== load) {
      let effort = null, deficit = null;
      if (this.hasMotion) ({ activations: effort, deficit } = await this.local.motionWithDeficit([[s.target, s.velocity, s.acceleration, load]]));
      const drawn = await this.drawnFor([s.target], [load]);
      this.liveCache = { seq: s.seq, load, drawn, effort: effort ?? drawn, notHeld: Boolean(deficit && deficit[0] !== 0) };
    }
    this.state.angle = s.target;
    const c = this.liveCache;
    return { drawn: c.drawn, effort: c.effort, load, live: s, notHeld: c.notHeld };
  }

  // A live state reached the screen (the frame that ended at `now`).
  liveDrawn({ sample, achieved, effort, notHeld }, now) {
    this.live.drawn(sample, achieved, now);
    const t = sample.arrived / 1000;
    this.liveGraphs.add({ t, effort, angle: sample.angle, achieved, target: this.exerciseUi.target(sample.arrived) ?? NaN, notHeld });
    this.exerciseUi.drawn(sample, effort, notHeld);
  }

  // {drawn, effort, load, k?, target?} for the state to draw now.
  async activationsForState() {
    const s = this.state;
    if (this.liveOn && this.live.sample) return this.liveState();
    if (this.player.playing) {
      const frame = this.player.frame(performance.now());
      s.angle = frame.target;
      return frame;
    }
    if (this.playing) {
      const t = await this.playTable();
      const u = ((((performance.now() - this.playStart) / 1000) % PLAY_PERIOD_S) / PLAY_PERIOD_S) * PLAY_SAMPLES;
      const k = Math.floor(u) % PLAY_SAMPLES, k1 = (k + 1) % PLAY_SAMPLES, f = u - Math.floor(u);
      for (let j = 0; j < 5; j++) {
        this.playDrawn[j] = t.drawn[5 * k + j] * (1 - f) + t.drawn[5 * k1 + j] * f;
        this.playEffort[j] = t.effort[5 * k + j] * (1 - f) + t.effort[5 * k1 + j] * f;
      }
      s.angle = t.angles[k] * (1 - f) + t.angles[k1] * f;
      return { drawn: this.playDrawn, effort: this.playEffort, load: s.load };
    }
    if (s.driver === 'angle') {
      const effort = this.hasMotion ? await this.local.activationsForMotion(s.angle, 0, 0, s.load) : null;
      const drawn = this.loadInput ? effort : await this.local.activationsForAngle(s.angle);
      return { drawn, effort: effort ?? drawn, load: s.load };
    }
    return { drawn: s.activations, effort: s.activations, load: 0 };
  }

  // Where a frame's time goes, measured on this thread (performance.now): per state the lookup of
  // its activations, the inference and the buffer work (colours, normals); per frame the whole
  // tick and, inside it, the draw call submission. The rasterising itself runs in the GPU
  // process (SwiftShader in a software setup) and shows in a Chrome trace, not here.
  resetProfile() {
    this.prof = { frames: 0, states: 0, tickMs: 0, renderMs: 0, activationsMs: 0, inferenceMs: 0, buffersMs: 0, t0: performance.now() };
  }

  profile() {
    const p = this.prof, f = Math.max(p.frames, 1), s = Math.max(p.states, 1), wall = performance.now() - p.t0;
    return { frames: p.frames, states: p.states, wallMs: wall, fps: (1000 * p.frames) / wall,
      perFrame: { tickMs: p.tickMs / f, renderSubmitMs: p.renderMs / f },
      perState: { activationsMs: p.activationsMs / s, inferenceMs: p.inferenceMs / s, buffersMs: p.buffersMs / s },
      nodes: this.meta.n_nodes, triangles: this.meta.triangles.length, renderScale: this.scene.renderScale };
  }

  async infer() {
    const serial = this.serial;
    const ta = performance.now();
    const next = await this.activationsForState();
    const t0 = performance.now();
    // one contract on both places: the server's deformation is fed the same load (SPEC 9)
    const local = this.place === 'wasm';
    const r = await (local ? this.local : this.server).deform(next.drawn, local && this.loadInput ? 'float32' : this.tier, next.load);
    const ms = performance.now() - t0;
    this.prof.activationsMs += t0 - ta;
    this.prof.inferenceMs += ms;
    this.inferenceMs = Number.isFinite(this.inferenceMs) ? 0.8 * this.inferenceMs + 0.2 * ms : ms;
    this.effort.set(next.effort);
    if (this.state.driver !== 'activations' || this.player.playing) this.state.activations.set(next.effort);
    const tb = performance.now();
    this.scene.setPositions(r.positions);
    this.prof.buffersMs += performance.now() - tb;
    this.prof.states++;
    const angle = Number.isFinite(r.angle) ? r.angle : 0; // NaN: the export has no angle output
    this.scene.setElbowAngle(angle);
    this.elbowAngle = angle;
    if (next.k !== undefined) this.player.record(next.k, angle, next.target);
    if (next.live) this.pendingLive = { sample: next.live, achieved: angle, effort: Float32Array.from(next.effort), notHeld: next.notHeld };
    this.states++;
    this.applied = serial;
    // the panel's numbers at most every 100 ms: each change is a layout, paint and raster of the panel
    const now = performance.now();
    if (!(this.playing || this.player.playing || this.liveOn) || now - (this.shownAt || 0) > 100) {
      this.shownAt = now;
      this.controls.show(this.effort, angle);
    }
    if (this.mode === 'auto' && this.monitor.add(ms)) {
      const m = this.measured.find((x) => x.place === this.place && x.tier === this.tier);
      if (m) m.ms = this.monitor.ema;
      this.pickAuto(m);
    }
  }

  tick(now) {
    const tickStart = performance.now();
    this.frames.push(now);
    while (this.frames.length && now - this.frames[0] > 1000) this.frames.shift();
    if (this.frames.length > 1) this.fps = ((this.frames.length - 1) * 1000) / (now - this.frames[0]);
    if (this.playing || this.player.playing) this.touch();
    if (!this.busy && this.applied < this.serial) {
      this.busy = true;
      this.infer().catch((e) => { ui.status(String(e.message || e), true); this.fail(e); })
        .finally(() => { this.busy = false; });
    }
    // a new resolution before drawing: resizing clears the canvas, and a frame drawn before the
    // resize would be shown blank
    if ((this.scaleAt || 0) < now - 500 && this.frames.length > 10) { this.scaleAt = now; this.scene.adaptResolution(this.fps); }
    this.exerciseUi.tick(now);
    const fresh = this.pendingLive; // set by a finished infer(): drawn by this render
    this.pendingLive = null;
    const tr = performance.now();
    this.scene.render();
    this.prof.renderMs += performance.now() - tr;
    if (fresh) this.liveDrawn(fresh, performance.now());
    if (this.liveOn) this.liveGraphs.draw(now);
    this.waiters = this.waiters.filter((w) => (this.applied >= w.serial && !this.busy ? (w.resolve(), false) : true));
    if ((this.hudAt || 0) < now - 250) { this.hudAt = now; this.hud(this.stats()); this.controls.showLoad(); this.liveUi.show(); }
    this.prof.frames++;
    this.prof.tickMs += performance.now() - tickStart;
  }

  fail(e) {
    this.applied = this.serial; // do not retry the failed state every frame
    for (const w of this.waiters) w.reject(e);
    this.waiters = [];
  }

  stats() {
    return { fps: this.fps, inferenceMs: this.inferenceMs, backend: this.place, tier: this.tier, mode: this.mode,
      states: this.states, renderScale: this.scene.renderScale, elbowAngle: this.elbowAngle, playing: Boolean(this.playing),
      angle: this.state.angle, load: this.state.load, held: this.held(this.state.angle), effort: Array.from(this.effort),
      colours: this.scene.buffers.activations ? 'activation' : 'displacement', legendMm: this.scene.buffers.scaleMm,
      playSpan: this.table?.span ?? null, recording: this.player.summary(), viewAlongHinge: this.scene.viewAlongHinge(),
      live: this.liveStats() };
  }

  liveStats() {
    const live = this.live;
    return { on: Boolean(this.liveOn), source: this.liveUi?.mode() ?? 'off', sample: live.sample, counts: { ...live.counts },
      latency: live.latency(), message: document.getElementById('live-note').textContent, drawnSamples: live.log.length,
      exercise: this.exerciseUi?.running() ?? false, ghost: this.ghost.group.visible ? this.exerciseUi.target(performance.now()) : null };
  }
}

const viewer = new Viewer();
viewer.hud = ui.hud();
const ready = viewer.start().catch((e) => { ui.status(`could not start: ${e.message || e}`, true); throw e; });

// The in-browser float32 state for activations and a load (kg): a load only for a deformation
// model the browser can feed it to, else refused.
async function localState(a, loadKg) {
  if (loadKg && !viewer.local.takesLoad) throw new Error('the in-browser deformation model takes no load');
  return viewer.local.deform(Float32Array.from(a), 'float32', loadKg);
}

window.persival = {
  ready,
  viewer,
  async predict(a, loadKg = 0) { return Float32Array.from((await localState(a, loadKg)).positions); },
  async predictAngle(a, loadKg = 0) { return (await localState(a, loadKg)).angle; },
  async predictServer(a, loadKg = 0) { return Float32Array.from((await viewer.server.deform(Float32Array.from(a), 'float32', loadKg)).positions); },
  // (angle, load) -> activations, as the page computes them for setAngle (the contract's second half)
  activationsFor: (deg, load = 0) => viewer.drawnFor([deg], [load]),
  setActivations: (a) => viewer.setActivations(a),
  setAngle: (deg, load) => viewer.setAngle(deg, load),
  setLoad: (kg) => viewer.controls.setLoad(kg),
  held: (deg) => viewer.held(deg),
  openRecording: (text, name, column) => viewer.controls.openRecording(text, name, column),
  setColourMode: (activation) => viewer.setColourMode(activation),
  setBackend: (mode, tier) => { viewer.setMode(mode, tier); return viewer.rendered(); },
  play: (on) => viewer.controls.play(on),
  // live input and the exercise (tests, and pages embedding the viewer)
  live: (source) => viewer.liveUi.select(source),
  liveLog: () => viewer.live.log,
  webcam: () => { const w = viewer.liveUi.source(); return w?.history ? { counts: { ...w.counts }, last: w.last, history: w.history } : null; },
  startExercise: () => viewer.exerciseUi.start(),
  finishExercise: () => viewer.exerciseUi.finish(),
  exerciseResult: () => viewer.exerciseResult ?? null,
  stats: () => viewer.stats(),
  profile: (reset = false) => { const p = viewer.profile(); if (reset) viewer.resetProfile(); return p; },
};
