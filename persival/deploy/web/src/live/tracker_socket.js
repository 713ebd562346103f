// A motion tracker through the server's relay (/ws/tracker, subscribed): each JSON message is an
// elbow angle or the orientations of the upper arm and the forearm (docs/viewer.md, "Live").
// Messages the page cannot use are reported, never applied; silence and a closed connection
// are reported too; the connection is retried every few seconds.
import { flexionFromQuaternions, unitQuaternion } from './geometry.js';

export const STALE_MS = 1000; // no sample for this long: the tracker has stopped
const RETRY_MS = 2000;

// {angle, t} from one message, or {error}. t: the tracker's own time stamp (s) when it sent one.
export function readMessage(text) {
  let m;
  try { m = JSON.parse(text); } catch { return { error: 'a message that is not JSON' }; }
  if (m === null || typeof m !== 'object' || Array.isArray(m)) return { error: 'a message that is not a JSON object' };
  if (m.type === 'status') return { status: m };
  if (m.error !== undefined) return { error: `the relay says: ${m.error}` };
  const t = m.t === undefined ? null : m.t;
  if (t !== null && !(typeof t === 'number' && Number.isFinite(t))) return { error: `t = ${JSON.stringify(m.t)} is not a time in seconds` };
  if ('elbow_deg' in m) {
    if (!(typeof m.elbow_deg === 'number' && Number.isFinite(m.elbow_deg))) {
      return { error: `elbow_deg = ${JSON.stringify(m.elbow_deg)} is not a finite number` };
    }
    return { angle: m.elbow_deg, t };
  }
  if ('upper_arm' in m || 'forearm' in m) {
    const upper = unitQuaternion(m.upper_arm), fore = unitQuaternion(m.forearm);
    if (!upper || !fore) return { error: 'upper_arm and forearm must be unit quaternions [w, x, y, z]' };
    let axis = [1, 0, 0];
    if (m.axis !== undefined) {
      if (!(Array.isArray(m.axis) && m.axis.length === 3 && m.axis.every(Number.isFinite) && Math.hypot(...m.axis) > 0)) {
        return { error: 'axis must be a non-zero vector [x, y, z]' };
      }
      axis = m.axis;
    }
    return { angle: flexionFromQuaternions(upper, fore, axis), t };
  }
  return { error: `a message with neither elbow_deg nor upper_arm and forearm (keys: ${Object.keys(m).slice(0, 6).join(', ') || 'none'})` };
}

export class TrackerSocket {
  // onSample({angle, t, arrived}); onProblem(text) for one clear message; onOk() when data flows
  constructor({ onSample, onProblem, onOk }) {
    Object.assign(this, { onSample, onProblem, onOk });
    this.ws = null; this.running = false; this.lastAt = null; this.heardAt = null; this.publishers = null;
    this.counts = { messages: 0, samples: 0, rejected: 0 };
  }

  start() {
    this.running = true;
    this.connect();
    this.watch = setInterval(() => this.checkStale(), 250);
  }

  stop() {
    this.running = false;
    clearInterval(this.watch);
    clearTimeout(this.retry);
    if (this.ws) { this.ws.onclose = null; this.ws.close(); }
    this.ws = null;
  }

  connect() {
    const url = new URL('ws/tracker?role=subscribe', document.baseURI);
    url.protocol = url.protocol === 'https:' ? 'wss:' : 'ws:';
    const ws = new WebSocket(url.href);
    this.ws = ws;
    ws.onopen = () => { if (this.lastAt === null) this.onProblem('connected to the relay; waiting for the tracker'); };
    ws.onmessage = (ev) => this.receive(ev.data, performance.now());
    ws.onclose = () => {
      this.ws = null;
      if (!this.running) return;
      this.onProblem(`no connection to the tracker relay (${url.pathname}); retrying`);
      this.retry = setTimeout(() => this.running && this.connect(), RETRY_MS);
    };
  }

  receive(data, arrived) {
    this.counts.messages++;
    if (typeof data !== 'string') { this.reject('a binary message'); return; }
    const r = readMessage(data);
    if (r.status) {
      if (r.status.publishers > (this.publishers ?? 0)) this.heardAt = arrived; // a tracker came: silence counts from now
      this.publishers = r.status.publishers;
      if (this.publishers === 0) this.onProblem('no tracker is connected to the relay; the arm holds its last state');
      return;
    }
    this.heardAt = arrived; // the tracker sends, usable or not: not silent
    if (r.error) { this.reject(r.error); return; }
    this.lastAt = arrived;
    this.counts.samples++;
    this.onSample({ angle: r.angle, t: r.t, arrived });
  }

  reject(why) {
    this.counts.rejected++;
    this.onProblem(`the tracker sends data the page cannot use (${why}); the arm holds its last valid state`);
  }

  checkStale() {
    if (this.heardAt === null || this.publishers === 0) return;
    const quiet = performance.now() - this.heardAt;
    if (quiet > STALE_MS) this.onProblem(`the tracker stopped sending ${(quiet / 1000).toFixed(1)} s ago; the arm holds its last state`, true);
  }
}
