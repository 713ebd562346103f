// The panel's "Live" section: off / webcam / tracker, the arm and the visibility threshold of the
// webcam, the one message line and the live readout (angle, velocity, acceleration, latency).
import { TrackerSocket } from './tracker_socket.js';
import { Webcam } from './webcam.js';

export function setupLive(v) {
  const $ = (id) => document.getElementById(id);
  const note = $('live-note'), readout = $('live-readout'), side = $('live-side'), vis = $('live-visibility'), geometry = $('live-geometry');
  const say = (text, problem = false) => {
    if (note.textContent !== text) note.textContent = text;
    note.classList.toggle('refused', problem);
  };
  v.live.note = say;
  const handlers = { onSample: (s) => v.live.push(s), onProblem: (text) => v.live.problem(text), onOk: () => {} };
  let source = null, mode = 'off';

  const buttons = () => { for (const b of document.querySelectorAll('#live-source button')) b.classList.toggle('on', b.dataset.source === mode); };

  async function select(next) {
    if (next === mode) return { ok: true, source: mode };
    source?.stop();
    source = null;
    v.stopLive();
    mode = next; buttons();
    if (next === 'off') { say(''); readout.textContent = ''; $('webcam-view').hidden = true; return { ok: true, source: 'off' }; }
    if (!v.hasAngleModel) { mode = 'off'; buttons(); say('this export has no activation model: it cannot follow an elbow', true); return { ok: false }; }
    v.startLive(next);
    if (next === 'tracker') {
      source = new TrackerSocket(handlers);
      source.start();
      return { ok: true, source: next };
    }
    source = new Webcam({ ...handlers, preview: $('webcam-view'), side: side.value, visibility: Number(vis.value),
      geometry: geometry.value });
    try {
      await source.start();
      return { ok: true, source: next };
    } catch (e) {
      const message = String(e.message || e);
      if (mode === next) { source = null; mode = 'off'; buttons(); v.stopLive(); }
      say(message, true); // after stopLive: the message stays
      return { ok: false, message };
    }
  }

  for (const b of document.querySelectorAll('#live-source button')) b.addEventListener('click', () => select(b.dataset.source));
  side.addEventListener('change', () => { if (source instanceof Webcam) source.side = side.value; });
  geometry.addEventListener('change', () => { if (source instanceof Webcam) source.geometry = geometry.value; });
  vis.addEventListener('input', () => {
    $('live-visibility-out').value = Number(vis.value).toFixed(2);
    if (source instanceof Webcam) source.visibility = Number(vis.value);
  });

  return {
    select,
    source: () => source,
    mode: () => mode,
    // the readout, at most every 250 ms (the HUD's pace)
    show() {
      const s = v.live.sample;
      if (!s || mode === 'off') return;
      const lat = v.live.latency();
      readout.textContent = `angle ${s.angle.toFixed(1)}°, velocity ${s.velocity.toFixed(0)}°/s, acceleration ${s.acceleration.toFixed(0)}°/s²` +
        (lat ? `; input to drawn frame ${lat.median.toFixed(0)} ms (median), ${lat.p95.toFixed(0)} ms (95 %)` : '') +
        (v.live.counts.clamped ? `; ${v.live.counts.clamped} clamped` : '');
    },
  };
}
