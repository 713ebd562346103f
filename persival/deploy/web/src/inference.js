// Two places to compute a state: in this browser (onnxruntime-web, WebAssembly) or on the server
// (the /ws WebSocket, binary replies). Both answer {positions, angle, activations}.
import * as ort from 'onnxruntime-web/wasm';

export function configureOrt() {
  // The runtime's .mjs/.wasm are served by our own server (dist/ort/), never a CDN.
  ort.env.wasm.wasmPaths = new URL('ort/', document.baseURI).href;
  // One thread: the models are small (threads only add hand-off latency) and a page need not be
  // cross-origin isolated to run it.
  ort.env.wasm.numThreads = 1;
  ort.env.wasm.proxy = false;
}

async function fetchBytes(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return new Uint8Array(await r.arrayBuffer());
}

export class LocalEngine {
  constructor(meta) {
    this.meta = meta;
    this.sessions = new Map();
    this.input = new Float32Array(5);
    this.zero = new Float32Array(1);
    // An export whose deformation graph takes the load also lists `load_variant`
    // (deformation_load.onnx: the same graph with `load_kg` a required input). onnxruntime-web
    // cannot feed deformation.onnx's optional load (an input backed by an initializer), so the
    // float32 tier runs that file instead, and is always fed the load (0 kg when none).
    this.loadVariant = meta.models.deformation.load_variant ?? null;
    this.takesLoad = Boolean(this.loadVariant); // else set by loadInput()
  }

  async session(file) {
    if (!this.sessions.has(file)) {
      const bytes = await fetchBytes(`artifacts/${file}`);
      this.sessions.set(file, await ort.InferenceSession.create(bytes, {
        executionProviders: ['wasm'], graphOptimizationLevel: 'all',
        logSeverityLevel: 3, // errors only: an optional input backed by an initializer draws a warning at every load
      }));
    }
    return this.sessions.get(file);
  }

  // The file a tier runs: float32 is the required-load file where the export has one (only that
  // one is downloaded), else deformation.onnx.
  variantFile(tier) {
    const d = this.meta.models.deformation;
    return tier === 'float32' && d.load_variant ? d.load_variant.file : d.variants[tier].file;
  }

  // Whether the float32 deformation graph is fed `load_kg`: always with the load variant; else only
  // where deformation.onnx has it as a true input (onnxruntime-web accepts only the graph's true
  // inputs, so an optional input backed by an initializer, 0 kg, cannot be fed here).
  async loadInput() {
    if (!('load_kg' in (this.meta.models.deformation.inputs || {}))) return false;
    this.takesLoad = (await this.session(this.variantFile('float32'))).inputNames.includes('load_kg');
    return this.takesLoad;
  }

  // `load_kg` [1, 1] for a float32 graph that takes it (it broadcasts over the batch), else none.
  loadFeed(tier, load) {
    if (!(this.takesLoad && tier === 'float32')) return {};
    return { load_kg: new ort.Tensor('float32', load ? new Float32Array([load]) : this.zero, [1, 1]) };
  }

  // load (kg): fed to a deformation graph that takes it (`load_kg`, a model that solves the
  // elbow's equilibrium with the load in the hand; 0 kg when none); other graphs have no such input.
  async deform(activations, tier = 'float32', load = 0) {
    const s = await this.session(this.variantFile(tier));
    this.input.set(activations);
    const out = await s.run({ activations: new ort.Tensor('float32', this.input, [1, 5]), ...this.loadFeed(tier, load) });
    const angle = out.elbow_angle_deg ? out.elbow_angle_deg.data[0] : NaN; // optional output
    return { positions: out.positions.data, angle, activations: this.input };
  }

  // Positions of a batch of activations (flat, 5 per state), without a load.
  async deformBatch(flat, tier = 'float32') {
    const s = await this.session(this.variantFile(tier));
    const activations = new ort.Tensor('float32', Float32Array.from(flat), [flat.length / 5, 5]);
    const out = await s.run({ activations, ...this.loadFeed(tier, 0) });
    return out.positions.data;
  }

  async activationsForAngle(deg) {
    const m = this.meta.models.activation_angle;
    const s = await this.session(m.file);
    const out = await s.run({ [m.input]: new ort.Tensor('float32', new Float32Array([deg]), [1, 1]) });
    return Float32Array.from(out[m.output].data);
  }

  async angleBatch(angles) {
    const m = this.meta.models.activation_angle;
    const s = await this.session(m.file);
    const out = await s.run({ [m.input]: new ort.Tensor('float32', Float32Array.from(angles), [angles.length, 1]) });
    return Float32Array.from(out[m.output].data);
  }

  async motionBatch(rows) {
    const m = this.meta.models.activation_motion;
    const s = await this.session(m.file);
    const out = await s.run({ [m.input]: new ort.Tensor('float32', Float32Array.from(rows.flat()), [rows.length, 4]) });
    return Float32Array.from(out[m.output].data);
  }

  // Activations and, where the graph has it, the moment deficit (N mm, 0 where the muscles hold).
  async motionWithDeficit(rows) {
    const m = this.meta.models.activation_motion;
    const s = await this.session(m.file);
    const flat = new Float32Array(rows.length * 4);
    rows.forEach((r, i) => flat.set(r, 4 * i));
    const out = await s.run({ [m.input]: new ort.Tensor('float32', flat, [rows.length, 4]) });
    const deficit = out.moment_deficit_Nmm ? Float32Array.from(out.moment_deficit_Nmm.data) : null;
    return { activations: Float32Array.from(out[m.output].data), deficit };
  }

  async activationsForMotion(angle, velocity, acceleration, load) {
    const m = this.meta.models.activation_motion;
    const s = await this.session(m.file);
    const x = new Float32Array([angle, velocity, acceleration, load]);
    const out = await s.run({ [m.input]: new ort.Tensor('float32', x, [1, 4]) });
    return Float32Array.from(out[m.output].data);
  }
}

const HEADER_BYTES = 28; // uint32 id, float32 angle, float32 x 5 activations (protocol.py)

export class ServerEngine {
  constructor(nNodes) {
    this.nNodes = nNodes;
    this.pending = new Map();
    this.nextId = 1;
    this.ws = null;
  }

  connect() {
    if (this.ready) return this.ready;
    const url = new URL('ws', document.baseURI);
    url.protocol = url.protocol === 'https:' ? 'wss:' : 'ws:';
    this.ready = new Promise((resolve, reject) => {
      const ws = new WebSocket(url.href);
      ws.binaryType = 'arraybuffer';
      ws.onopen = () => { this.ws = ws; resolve(this); };
      ws.onerror = () => reject(new Error('the server WebSocket is not reachable'));
      ws.onclose = () => { this.ws = null; this.ready = null; this.failAll('connection closed'); };
      ws.onmessage = (ev) => this.receive(ev.data);
    });
    return this.ready;
  }

  failAll(reason) {
    for (const p of this.pending.values()) p.reject(new Error(reason));
    this.pending.clear();
  }

  receive(data) {
    if (typeof data === 'string') {
      // Errors come as JSON text; with one request in flight it is the oldest pending one.
      const err = JSON.parse(data);
      const [id, p] = this.pending.entries().next().value || [];
      if (p) { this.pending.delete(id); p.reject(new Error(err.error || 'server error')); }
      return;
    }
    const view = new DataView(data);
    const id = view.getUint32(0, true);
    const p = this.pending.get(id);
    if (!p) return;
    this.pending.delete(id);
    p.resolve({
      angle: view.getFloat32(4, true),
      activations: new Float32Array(data, 8, 5),
      positions: new Float32Array(data, HEADER_BYTES, this.nNodes * 3),
    });
  }

  async request(body) {
    await this.connect();
    const id = this.nextId++ >>> 0;
    return new Promise((resolve, reject) => {
      this.pending.set(id, { resolve, reject });
      this.ws.send(JSON.stringify({ ...body, id, encoding: 'binary' }));
    });
  }

  deform(activations, tier = 'float32', load = 0) {
    return this.request({ activations: Array.from(activations), tier, ...(load ? { load_kg: load } : {}) });
  }
}
