// Smoothing made for live tracking: the One Euro filter (Casiez, Roussel and Vogel, CHI 2012), a
// first-order low-pass whose cutoff rises with the speed: little jitter when the arm is still,
// little lag when it moves. Velocity and acceleration come from the smoothed angle: each the
// low-passed finite difference of the one before (cutoff dCutoff), so noise is not amplified
// twice. Times in seconds, any (irregular) rate.

const alpha = (cutoffHz, dt) => {
  const tau = 1 / (2 * Math.PI * cutoffHz);
  return 1 / (1 + tau / dt);
};

export class OneEuroFilter {
  // minCutoff (Hz): the cutoff at rest; beta (s/unit): how fast it rises with the speed;
  // dCutoff (Hz): the cutoff of the speed estimate that drives it.
  constructor({ minCutoff = 1.0, beta = 0.05, dCutoff = 1.0 } = {}) {
    Object.assign(this, { minCutoff, beta, dCutoff });
    this.reset();
  }

  reset() { this.x = null; this.dx = 0; this.t = null; }

  filter(value, t) {
    if (this.x === null) { this.x = value; this.t = t; this.dx = 0; return value; }
    const dt = t - this.t;
    if (!(dt > 0)) return this.x; // a repeated or older sample changes nothing
    const rawDx = (value - this.x) / dt;
    this.dx += alpha(this.dCutoff, dt) * (rawDx - this.dx);
    const cutoff = this.minCutoff + this.beta * Math.abs(this.dx);
    this.x += alpha(cutoff, dt) * (value - this.x);
    this.t = t;
    return this.x;
  }
}

// Angle (deg) -> smoothed angle, velocity (deg/s) and acceleration (deg/s^2).
export class MotionFilter {
  constructor({ minCutoff = 1.0, beta = 0.05, dCutoff = 1.0, derivativeCutoff = 6.0 } = {}) {
    this.angle = new OneEuroFilter({ minCutoff, beta, dCutoff });
    this.derivativeCutoff = derivativeCutoff;
    this.reset();
  }

  reset() {
    this.angle.reset();
    this.last = null; // {t, angle, velocity}
    this.velocity = 0; this.acceleration = 0;
  }

  push(angleDeg, t) {
    const angle = this.angle.filter(angleDeg, t);
    if (this.last && t > this.last.t) {
      const dt = t - this.last.t, a = alpha(this.derivativeCutoff, dt);
      const velocity = this.velocity + a * ((angle - this.last.angle) / dt - this.velocity);
      this.acceleration += a * ((velocity - this.velocity) / dt - this.acceleration);
      this.velocity = velocity;
    }
    if (!this.last || t > this.last.t) this.last = { t, angle };
    return { angle, velocity: this.velocity, acceleration: this.acceleration };
  }
}

// Per source: a webcam's landmarks jitter by a few degrees from frame to frame at 15 to 30 Hz, a
// tracker's angles by a fraction of one at 60 Hz or more (docs/viewer.md, "Live").
export const FILTERS = {
  webcam: { minCutoff: 1.0, beta: 0.05, dCutoff: 1.0, derivativeCutoff: 4.0 },
  tracker: { minCutoff: 3.0, beta: 0.1, dCutoff: 2.0, derivativeCutoff: 8.0 },
};
