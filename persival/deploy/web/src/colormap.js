// Perceptually ordered colour scale (viridis stops), as a 256-entry lookup table so the per-frame
// colouring is one multiply and three loads per vertex.
const STOPS = [
  [0.267, 0.005, 0.329], [0.283, 0.141, 0.458], [0.254, 0.265, 0.530], [0.207, 0.372, 0.553],
  [0.164, 0.471, 0.558], [0.128, 0.567, 0.551], [0.135, 0.659, 0.518], [0.267, 0.749, 0.441],
  [0.478, 0.821, 0.318], [0.741, 0.873, 0.150], [0.993, 0.906, 0.144],
];

export const LUT = (() => {
  const lut = new Float32Array(256 * 3);
  for (let i = 0; i < 256; i++) {
    const t = (i / 255) * (STOPS.length - 1);
    const k = Math.min(Math.floor(t), STOPS.length - 2);
    const f = t - k;
    for (let c = 0; c < 3; c++) lut[3 * i + c] = STOPS[k][c] * (1 - f) + STOPS[k + 1][c] * f;
  }
  return lut;
})();

export function cssColor(t) {
  const i = 3 * Math.round(Math.min(Math.max(t, 0), 1) * 255);
  return `rgb(${(LUT[i] * 255) | 0}, ${(LUT[i + 1] * 255) | 0}, ${(LUT[i + 2] * 255) | 0})`;
}

// A round upper end for the legend (1, 2, 2.5, 5 x 10^k) so the ticks read as plain numbers.
export function niceCeil(x) {
  if (!(x > 0)) return 1;
  const p = 10 ** Math.floor(Math.log10(x));
  for (const m of [1, 2, 2.5, 5, 10]) if (m * p >= x) return m * p;
  return 10 * p;
}
