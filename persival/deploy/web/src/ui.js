// The control panel, the heads-up display and the legend; no model logic here.
import { cssColor } from './colormap.js';

export const SWATCH = ['#e76f51', '#f4a261', '#e9c46a', '#2a9d8f', '#8ab17d'];

export function buildSliders(muscles, onInput) {
  const host = document.getElementById('sliders');
  return muscles.map((name, i) => {
    const row = document.createElement('label');
    row.className = 'row';
    row.innerHTML = `<span><i class="swatch" style="background:${SWATCH[i]}"></i>${name}</span>` +
      `<input type="range" min="0" max="1" step="0.01" value="0" data-muscle="${i}"><output>0.00</output>`;
    host.appendChild(row);
    const input = row.querySelector('input');
    const out = row.querySelector('output');
    input.addEventListener('input', () => { out.value = Number(input.value).toFixed(2); onInput(i, Number(input.value)); });
    return { input, out, set(v) { input.value = v; out.value = Number(v).toFixed(2); } };
  });
}

export function drawLegend(maxMm, title) {
  document.querySelector('#legend .legend-title').textContent = title;
  const bar = document.getElementById('legend-bar');
  const ctx = bar.getContext('2d');
  for (let x = 0; x < bar.width; x++) {
    ctx.fillStyle = cssColor(x / (bar.width - 1));
    ctx.fillRect(x, 0, 1, bar.height);
  }
  const ticks = document.getElementById('ticks');
  ticks.innerHTML = '';
  for (let k = 0; k <= 4; k++) {
    const s = document.createElement('span');
    s.style.left = `${(k / 4) * 100}%`;
    const v = (maxMm * k) / 4;
    s.textContent = Number.isInteger(v) ? String(v) : v.toFixed(maxMm <= 1 ? 2 : 1);
    ticks.appendChild(s);
  }
}

export function hud() {
  const fps = document.getElementById('fps');
  const ms = document.getElementById('ms');
  const where = document.getElementById('where');
  return (s) => {
    fps.textContent = s.fps.toFixed(0);
    ms.textContent = Number.isFinite(s.inferenceMs) ? s.inferenceMs.toFixed(2) : '-';
    where.textContent = `${s.backend === 'wasm' ? 'in browser (WebAssembly)' : 'server (WebSocket)'}, ${s.tier}` +
      (s.mode === 'auto' ? ', auto' : '');
  };
}

export function status(text, error = false) {
  const el = document.getElementById('status');
  el.textContent = text;
  el.classList.toggle('error', error);
}

export function setModeButtons(mode) {
  for (const b of document.querySelectorAll('#backend button')) b.classList.toggle('on', b.dataset.mode === mode);
}
