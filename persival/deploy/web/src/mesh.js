// Per-frame geometry work on raw typed arrays, allocated once: the model writes positions, we
// colour them and recompute area-weighted vertex normals (a bulging muscle must be lit as it is
// now, not as it was in the reference pose). Two colourings: displacement |x - X| from the
// hanging arm (the state at zero activations, as the FE pictures measure it), or each muscle in
// one colour by its activation.
import { LUT } from './colormap.js';

export class MuscleBuffers {
  constructor(reference, triangles, ranges) {
    this.n = reference.length / 3;
    this.reference = reference; // replaced by the hanging arm once the model has run
    this.index = triangles;
    this.ranges = ranges; // per muscle [first node, node count]
    this.positions = new Float32Array(reference);
    this.normals = new Float32Array(reference.length);
    this.colors = new Float32Array(reference.length);
    this.displacement = new Float32Array(this.n);
    this.scaleMm = 1;
    this.activations = null; // set: colour by activation instead of displacement
  }

  update(positions) {
    this.positions.set(positions);
    if (this.activations) this.colourByActivation(this.activations);
    else this.colour();
    this.computeNormals();
  }

  colourByActivation(a) {
    const colors = this.colors;
    this.ranges.forEach(([start, count], m) => {
      const k = 3 * Math.min(255, Math.max(0, Math.round(a[m] * 255)));
      for (let j = 3 * start, end = 3 * (start + count); j < end; j += 3) {
        colors[j] = LUT[k]; colors[j + 1] = LUT[k + 1]; colors[j + 2] = LUT[k + 2];
      }
    });
  }

  colour() {
    const { positions: x, reference: X, colors, displacement } = this;
    const inv = 255 / this.scaleMm;
    let max = 0;
    for (let i = 0, j = 0; i < this.n; i++, j += 3) {
      const dx = x[j] - X[j], dy = x[j + 1] - X[j + 1], dz = x[j + 2] - X[j + 2];
      const d = Math.sqrt(dx * dx + dy * dy + dz * dz);
      displacement[i] = d;
      if (d > max) max = d;
      const k = 3 * Math.min(255, (d * inv) | 0);
      colors[j] = LUT[k]; colors[j + 1] = LUT[k + 1]; colors[j + 2] = LUT[k + 2];
    }
    this.maxDisplacement = max;
  }

  computeNormals() {
    const p = this.positions, nrm = this.normals, idx = this.index;
    nrm.fill(0);
    for (let t = 0; t < idx.length; t += 3) {
      const a = 3 * idx[t], b = 3 * idx[t + 1], c = 3 * idx[t + 2];
      const ux = p[b] - p[a], uy = p[b + 1] - p[a + 1], uz = p[b + 2] - p[a + 2];
      const vx = p[c] - p[a], vy = p[c + 1] - p[a + 1], vz = p[c + 2] - p[a + 2];
      const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      nrm[a] += nx; nrm[a + 1] += ny; nrm[a + 2] += nz;
      nrm[b] += nx; nrm[b + 1] += ny; nrm[b + 2] += nz;
      nrm[c] += nx; nrm[c + 1] += ny; nrm[c + 2] += nz;
    }
    for (let j = 0; j < nrm.length; j += 3) {
      const l = Math.hypot(nrm[j], nrm[j + 1], nrm[j + 2]) || 1;
      nrm[j] /= l; nrm[j + 1] /= l; nrm[j + 2] /= l;
    }
  }
}
