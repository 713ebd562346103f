// Wires the panel to the viewer: sliders and selectors in, shown values and refusals out.
import * as ui from './ui.js';

export function setupControls(v) {
  const meta = v.meta;
  const $ = (id) => document.getElementById(id);
  const sliders = ui.buildSliders(meta.muscles, (i, value) => {
    const a = Array.from(v.state.activations);
    a[i] = value;
    v.setActivations(a).catch(() => {});
  });
  const angle = $('angle'), angleOut = $('angle-out');
  [angle.min, angle.max] = v.range.map(String);
  const note = (text, refused = false) => { const el = $('load-note'); el.textContent = text; el.classList.toggle('refused', refused); };
  let refusedAt = 0; // a refusal stays on screen a few seconds before the "holds at most" line returns

  angle.addEventListener('input', async () => {
    const result = await v.setAngle(Number(angle.value)).catch((e) => ({ ok: false, message: e.message }));
    if (!result.ok) { angle.value = String(v.state.angle); note(result.message, true); refusedAt = performance.now(); }
  });

  const load = $('load'), loadOut = $('load-out');
  async function setLoad(kg) {
    const result = await v.setLoad(kg);
    if (!result.ok) { note(result.message, true); refusedAt = performance.now(); }
    load.value = String(v.state.load);
    loadOut.value = `${v.state.load.toFixed(1)} kg`;
    if (result.ok && v.playing) v.table = null; // the cycle's span and activations follow the load
    return result;
  }
  if (v.hasMotion) {
    $('load-row').hidden = false;
    const max = v.holdable?.maxLoad ?? meta.models.activation_motion.max_load_kg ?? 5;
    load.max = String(max); // bounded by the model: no more than it holds anywhere
    load.value = '0';
    loadOut.value = '0.0 kg';
    load.addEventListener('change', () => setLoad(Number(load.value)));
    load.addEventListener('input', () => { loadOut.value = `${Number(load.value).toFixed(1)} kg`; });
  }

  const playBtn = $('play');
  if (!v.hasAngleModel) { angle.disabled = true; playBtn.disabled = true; }
  const play = (on = !v.playing) => {
    if (on) {
      const span = v.playSpan();
      if (!span.ok) { note(span.message, true); refusedAt = performance.now(); return span; }
      v.player.stop();
      v.table = null;
      v.playStart = performance.now();
    } else v.state.driver = 'angle';
    v.playing = on;
    playBtn.innerHTML = on ? '&#10073;&#10073; pause' : '&#9654; play flexion-extension';
    v.touch();
    return { ok: true };
  };
  playBtn.addEventListener('click', () => play());

  // Recorded movements: a file from disk, played at its own speed with live graphs.
  async function openRecording(text, name, column = null) {
    try {
      if (v.playing) play(false);
      if (v.liveOn) await v.liveUi.select('off'); // a recording and a live source share the graphs
      const summary = await v.player.open(text, name, column);
      $('recording-note').textContent = `${summary.file}: ${summary.frames} frames, ${summary.duration.toFixed(1)} s ` +
        `(${summary.column}); ${summary.framesClamped} clamped to ${v.range[0].toFixed(0)}-${v.range[1].toFixed(0)}°` +
        (v.hasMotion ? `; ${summary.framesNotHeld} where the load cannot be held` : '');
      $('recording-note').classList.remove('refused');
      $('replay').disabled = false;
      return { ok: true, ...summary };
    } catch (e) {
      $('recording-note').textContent = String(e.message || e);
      $('recording-note').classList.add('refused');
      return { ok: false, message: String(e.message || e) };
    }
  }
  $('recording').addEventListener('change', async (ev) => {
    const file = ev.target.files[0];
    if (file) await openRecording(await file.text(), file.name);
    ev.target.value = '';
  });
  $('replay').addEventListener('click', () => { if (v.player.rec) { if (v.playing) play(false); v.player.start(); } });

  $('activation-colours').addEventListener('change', (ev) => v.setColourMode(ev.target.checked));

  const tier = $('tier');
  for (const t of v.tiers) tier.add(new Option(t, t));
  tier.addEventListener('change', () => v.setMode(v.mode === 'auto' ? 'wasm' : v.mode, tier.value));
  for (const b of document.querySelectorAll('#backend button')) b.addEventListener('click', () => v.setMode(b.dataset.mode));

  setupAR(v);
  let drawnDeg = null; // the angle last drawn: with the activation sliders driving, the model's answer
  return {
    play,
    setLoad,
    openRecording,
    sync() { ui.setModeButtons(v.mode); tier.value = v.tier; },
    show(activations, deg) {
      activations.forEach((a, i) => sliders[i].set(a));
      angle.value = String(v.state.driver === 'angle' && !v.playing && !v.player.playing ? v.state.angle : deg);
      angleOut.value = `${deg.toFixed(0)}°`;
      drawnDeg = deg;
    },
    // "holds at most X kg at Y°" under the load control, unless a refusal is still on screen
    showLoad() {
      if (!v.holdable || performance.now() - refusedAt < 4000) return;
      // the angle on screen: the one asked for, or the one the activation sliders give
      const deg = v.state.driver === 'angle' || drawnDeg === null ? v.state.angle : drawnDeg, held = v.held(deg);
      note(held < 0 ? `at ${deg.toFixed(0)}° not even the unloaded arm is held` :
        `at ${deg.toFixed(0)}° the muscles hold at most ${held.toFixed(2)} kg`);
    },
  };
}

async function setupAR(v) {
  const xr = navigator.xr;
  if (!xr || !(await xr.isSessionSupported('immersive-ar').catch(() => false))) return;
  const btn = document.getElementById('ar');
  btn.hidden = false;
  btn.addEventListener('click', async () => {
    // dom-overlay: the panel and the live graphs stay on screen over the camera image
    const session = await xr.requestSession('immersive-ar', { optionalFeatures: ['local-floor', 'dom-overlay'],
      domOverlay: { root: document.body } });
    v.scene.enterAR(session, v.graphs.rec ? v.graphs.canvas : null);
  });
}
