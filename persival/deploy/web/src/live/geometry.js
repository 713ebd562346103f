// Elbow angles from what trackers give: three joint positions (a pose tracker's shoulder, elbow
// and wrist landmarks) or two segment orientations (an IMU on the upper arm and one on the
// forearm, as unit quaternions). Flexion: 0 deg with the arm straight, 90 deg at a right angle.

const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const norm = (a) => Math.sqrt(dot(a, a));

// The angle (deg) between two vectors; NaN when either is (nearly) zero.
function between(u, v) {
  const nu = norm(u), nv = norm(v);
  if (!(nu > 1e-9 && nv > 1e-9)) return NaN;
  return (Math.acos(Math.min(1, Math.max(-1, dot(u, v) / (nu * nv)))) * 180) / Math.PI;
}

// Flexion from the shoulder, elbow and wrist positions ({x, y, z} or [x, y, z]): 180 deg minus
// the angle at the elbow between the upper arm and the forearm.
export function flexionFromPoints(shoulder, elbow, wrist) {
  const p = (q) => (Array.isArray(q) ? q : [q.x, q.y, q.z ?? 0]);
  const [s, e, w] = [shoulder, elbow, wrist].map(p);
  return 180 - between([s[0] - e[0], s[1] - e[1], s[2] - e[2]], [w[0] - e[0], w[1] - e[1], w[2] - e[2]]);
}

// v rotated by the unit quaternion q = [w, x, y, z].
export function rotate([w, x, y, z], v) {
  // t = 2 q_vec x v; v' = v + w t + q_vec x t
  const t = [2 * (y * v[2] - z * v[1]), 2 * (z * v[0] - x * v[2]), 2 * (x * v[1] - y * v[0])];
  return [v[0] + w * t[0] + (y * t[2] - z * t[1]), v[1] + w * t[1] + (z * t[0] - x * t[2]),
    v[2] + w * t[2] + (x * t[1] - y * t[0])];
}

// Flexion from the two segments' orientations: the angle between their long axes, each the
// sensor-frame `axis` (default x: the sensor strapped with its x axis along the bone, pointing
// away from the shoulder) turned by its quaternion. The forearm's twist about its own axis
// (pronation, supination) does not enter.
export function flexionFromQuaternions(upperArm, forearm, axis = [1, 0, 0]) {
  return between(rotate(upperArm, axis), rotate(forearm, axis));
}

// A quaternion [w, x, y, z] of finite numbers with a norm near 1 (it is then normalised), else null.
export function unitQuaternion(q) {
  if (!Array.isArray(q) || q.length !== 4 || !q.every((v) => typeof v === 'number' && Number.isFinite(v))) return null;
  const n = Math.hypot(...q);
  if (!(Math.abs(n - 1) < 0.1)) return null;
  return q.map((v) => v / n);
}
