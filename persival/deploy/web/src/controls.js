// Wires the panel to the viewer: sliders and selectors in, shown values out.
import * as ui from './ui.js';

export function setupControls(v) {
  const meta = v.meta;
  const sliders = ui.buildSliders(meta.muscles, (i, value) => {
    const a = Array.from(v.state.activations);
    a[i] = value;
    v.setActivations(a).catch(() => {});
  });
  const angle = document.getElementById('angle');
  const angleOut = document.getElementById('angle-out');
  [angle.min, angle.max] = v.range.map(String);
  angle.addEventListener('input', () => v.setAngle(Number(angle.value)).catch(() => {}));

  const load = document.getElementById('load');
  if (v.hasMotion) {
    document.getElementById('load-row').hidden = false;
    const max = meta.models.activation_motion.max_load_kg ?? 5;
    for (let kg = 0; kg <= max + 1e-9; kg += max > 5 ? 2 : 1) load.add(new Option(`${kg} kg in the hand`, String(kg)));
    load.addEventListener('change', () => {
      v.state.load = Number(load.value);
      if (v.state.driver === 'angle' || v.playing) v.setAngle(v.state.angle).catch(() => {});
    });
  }

  const playBtn = document.getElementById('play');
  if (!v.hasAngleModel) { angle.disabled = true; playBtn.disabled = true; }
  const play = (on = !v.playing) => {
    v.playing = on;
    if (on) v.playStart = performance.now();
    else v.state.driver = 'angle';
    playBtn.innerHTML = on ? '&#10073;&#10073; pause' : '&#9654; play flexion-extension';
    v.touch();
  };
  playBtn.addEventListener('click', () => play());

  const tier = document.getElementById('tier');
  for (const t of v.tiers) tier.add(new Option(t, t));
  tier.addEventListener('change', () => v.setMode(v.mode === 'auto' ? 'wasm' : v.mode, tier.value));
  for (const b of document.querySelectorAll('#backend button')) b.addEventListener('click', () => v.setMode(b.dataset.mode));

  setupAR(v);
  return {
    play,
    sync() { ui.setModeButtons(v.mode); tier.value = v.tier; },
    show(activations, deg) {
      activations.forEach((a, i) => sliders[i].set(a));
      angle.value = String(deg);
      angleOut.value = `${deg.toFixed(0)}°`;
    },
  };
}

async function setupAR(v) {
  const xr = navigator.xr;
  if (!xr || !(await xr.isSessionSupported('immersive-ar').catch(() => false))) return;
  const btn = document.getElementById('ar');
  btn.hidden = false;
  btn.addEventListener('click', async () => {
    const session = await xr.requestSession('immersive-ar', { optionalFeatures: ['local-floor', 'dom-overlay'],
      domOverlay: { root: document.body } });
    v.scene.enterAR(session);
  });
}
