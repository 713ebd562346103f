// The user's own elbow from a webcam: MediaPipe Pose (its full landmark model) runs in this page
// on each camera frame; camera frames never leave the browser. The elbow angle comes from the
// chosen arm's shoulder, elbow and wrist: in 3-D from the world landmarks (metres, about the
// hips; the default), or in the image plane (a camera at the user's side, the arm moving across
// the picture: the depth the tracker guesses does not enter). A landmark below the visibility
// threshold makes the frame "arm not found"; the arm then holds its last valid state.
//
// The tracker's files (dist/mediapipe/: pose.js, its WebAssembly, the graph and the model) are
// served by our own server and loaded only when the webcam is switched on.
import { flexionFromPoints } from './geometry.js';

// MediaPipe Pose's landmark indices (the person's own left and right)
export const LANDMARKS = { left: { shoulder: 11, elbow: 13, wrist: 15 }, right: { shoulder: 12, elbow: 14, wrist: 16 } };
const BODY = [[11, 12], [11, 13], [13, 15], [12, 14], [14, 16], [11, 23], [12, 24], [23, 24]];

let scriptLoad = null;
let shared = null; // one tracker for the page: its WebAssembly and models load once, whichever Webcam uses it
function loadPoseScript() {
  if (window.Pose) return Promise.resolve();
  scriptLoad ??= new Promise((resolve, reject) => {
    const s = document.createElement('script');
    s.src = new URL('mediapipe/pose.js', document.baseURI).href;
    s.onload = () => (window.Pose ? resolve() : reject(new Error('mediapipe/pose.js defines no Pose')));
    s.onerror = () => reject(new Error('mediapipe/pose.js could not be loaded'));
    document.head.appendChild(s);
  });
  return scriptLoad;
}

// One clear sentence per way getUserMedia fails.
export function cameraProblem(e) {
  const name = e && e.name;
  if (name === 'NotAllowedError' || name === 'SecurityError') {
    return 'the camera permission was denied: allow the camera for this page (or use a tracker)';
  }
  if (name === 'NotFoundError' || name === 'OverconstrainedError' || name === 'DevicesNotFoundError') return 'no camera found';
  if (name === 'NotReadableError' || name === 'TrackStartError') return 'the camera is in use by another program, or failed to start';
  return `the camera could not be started (${(e && e.message) || e})`;
}

export class Webcam {
  // onSample({angle, t, arrived, visibility, world}); onProblem(text); preview: the corner canvas
  constructor({ onSample, onProblem, preview, side = 'right', visibility = 0.5, geometry = '3d' }) {
    Object.assign(this, { onSample, onProblem, preview, side, visibility, geometry });
    this.video = document.createElement('video');
    this.video.muted = true; this.video.playsInline = true;
    this.running = false;
    this.counts = { frames: 0, persons: 0, armFound: 0, samples: 0 };
    this.last = null; // the last result's landmarks and angle
    this.history = []; // the last results (bounded), for the tests
  }

  async start() {
    if (!navigator.mediaDevices?.getUserMedia) throw new Error('no camera found (this browser offers no camera access here)');
    let stream;
    try {
      stream = await navigator.mediaDevices.getUserMedia({ video: { width: { ideal: 640 }, height: { ideal: 480 } }, audio: false });
    } catch (e) {
      throw new Error(cameraProblem(e));
    }
    this.stream = stream;
    this.video.srcObject = stream;
    await this.video.play();
    this.onProblem('loading the pose tracker');
    try {
      await loadPoseScript();
      if (!shared) {
        const pose = new window.Pose({ locateFile: (file) => new URL(`mediapipe/${file}`, document.baseURI).href });
        pose.setOptions({
          modelComplexity: 1, // the full landmark model (docs/viewer.md: why not the lite one)
          smoothLandmarks: false, // one smoothing only: ours (one_euro.js)
          enableSegmentation: false, minDetectionConfidence: 0.5, minTrackingConfidence: 0.5, selfieMode: false,
        });
        shared = pose.initialize().then(() => pose);
        shared.catch(() => { shared = null; });
      }
      this.pose = await shared;
      this.pose.onResults((r) => this.results(r));
    } catch (e) {
      this.stop();
      throw new Error(`the pose tracker could not be loaded: ${e.message || e}`);
    }
    this.running = true;
    this.onProblem('looking for a person');
    this.loop();
  }

  stop() {
    this.running = false;
    for (const track of this.stream?.getTracks() ?? []) track.stop();
    this.stream = null;
    this.video.srcObject = null;
  }

  // One frame at a time: the next is sent when the tracker has answered the last.
  async loop() {
    while (this.running) {
      if (this.video.readyState >= 2 && this.video.videoWidth > 0) {
        this.grabbed = performance.now();
        try { await this.pose.send({ image: this.video }); } catch (e) { this.onProblem(`the pose tracker failed on a frame: ${e.message || e}`); }
      }
      // a drawn frame between two tracked ones (the tracker runs on the page's thread), then a new camera frame
      await new Promise((resolve) => requestAnimationFrame(resolve));
      await new Promise((resolve) => (this.video.requestVideoFrameCallback ? this.video.requestVideoFrameCallback(resolve)
        : requestAnimationFrame(resolve)));
    }
  }

  results(r) {
    this.counts.frames++;
    const lm = r.poseLandmarks;
    this.draw(r.image, lm);
    if (!lm) { this.last = null; this.onProblem('no person found in the camera image; the arm holds its last state'); return; }
    this.counts.persons++;
    const idx = LANDMARKS[this.side];
    const joints = [idx.shoulder, idx.elbow, idx.wrist];
    const vis = Math.min(...joints.map((k) => lm[k].visibility ?? 1));
    const world = r.poseWorldLandmarks, w = r.image.width, h = r.image.height;
    const image = flexionFromPoints(...joints.map((k) => ({ x: lm[k].x * w, y: lm[k].y * h, z: 0 })));
    const spatial = world ? flexionFromPoints(...joints.map((k) => world[k])) : NaN;
    const angle = this.geometry === 'image' || !world ? image : spatial;
    this.last = { angle, image, spatial, geometry: this.geometry === 'image' || !world ? 'image' : '3d', visibility: vis,
      points: joints.map((k) => [lm[k].x * w, lm[k].y * h]) };
    this.history.push(this.last);
    if (this.history.length > 500) this.history.shift();
    if (!(vis >= this.visibility) || !Number.isFinite(angle)) {
      this.onProblem(`the ${this.side} arm is not in view (shoulder, elbow or wrist visibility ${vis.toFixed(2)} < ${this.visibility}); ` +
        'the arm holds its last state');
      return;
    }
    this.counts.armFound++;
    this.onSample({ angle, t: this.grabbed / 1000, arrived: this.grabbed });
  }

  // The camera image small in a corner, the landmarks over it (the chosen arm highlighted).
  draw(image, lm) {
    const c = this.preview;
    if (!c || !image) return;
    c.hidden = false;
    const w = c.width, h = Math.round((w * image.height) / image.width);
    if (c.height !== h) c.height = h;
    const g = c.getContext('2d');
    g.drawImage(image, 0, 0, w, h);
    if (!lm) return;
    const xy = (k) => [lm[k].x * w, lm[k].y * h];
    g.lineWidth = 2; g.strokeStyle = 'rgba(230,233,238,0.7)';
    for (const [a, b] of BODY) { g.beginPath(); g.moveTo(...xy(a)); g.lineTo(...xy(b)); g.stroke(); }
    const idx = LANDMARKS[this.side];
    g.strokeStyle = '#4fb3ff'; g.lineWidth = 3;
    g.beginPath(); g.moveTo(...xy(idx.shoulder)); g.lineTo(...xy(idx.elbow)); g.lineTo(...xy(idx.wrist)); g.stroke();
    for (const k of [idx.shoulder, idx.elbow, idx.wrist]) {
      g.fillStyle = (lm[k].visibility ?? 1) >= this.visibility ? '#4fb3ff' : '#ff7a7a';
      g.beginPath(); g.arc(...xy(k), 4, 0, 2 * Math.PI); g.fill();
    }
  }
}
