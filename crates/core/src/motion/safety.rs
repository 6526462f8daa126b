//! PC-side safety: the last filter before a setpoint becomes an RKorr.
//!
//! Per axis and cycle (dt), with v = the step this cycle divided by dt:
//! |v| ≤ vmax (step limit), |v − v_prev| ≤ amax·dt (step-change limit), and
//! the pose stays in the workspace box, braking early enough (at amax) that
//! the box is never left. Priority when they conflict: box, then velocity,
//! then acceleration — but from any state this filter produced they never
//! conflict (the braking bound is exact for the discrete motion), so all
//! three hold on every cycle. Non-finite requests are treated as "stop".
//! No allocation, no panics.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use super::MotionLimits;
use crate::geometry::Pose6;

/// The filter's state: the last pose sent and its per-cycle velocity.
#[derive(Clone, Debug, PartialEq)]
pub struct SafetyFilter {
    lo: Pose6,
    hi: Pose6,
    vmax: Pose6,
    amax: Pose6,
    dt: f64,
    p: Pose6,
    v: Pose6,
    /// Cycles on which the request was changed.
    pub clamped_cycles: u64,
}

/// Largest speed from which braking at `u` per cycle (u = a·dt) covers at
/// most `d` (the discrete motion p += v·dt, v -= u).
fn braking_speed(d: f64, dt: f64, u: f64) -> f64 {
    if d.is_nan() || d <= 0.0 {
        return 0.0;
    }
    if d.is_infinite() {
        return f64::INFINITY;
    }
    // S(n·u) = dt·u·n(n+1)/2; find the last full n, then the remainder.
    let k = d / (dt * u);
    let n = ((-1.0 + (1.0 + 8.0 * k).sqrt()) / 2.0).floor().max(0.0);
    (d / dt + u * n * (n + 1.0) / 2.0) / (n + 1.0)
}

impl SafetyFilter {
    /// A filter at rest at `start` (which should lie inside the box).
    pub fn new(lim: &MotionLimits, start: Pose6) -> Self {
        SafetyFilter {
            lo: lim.lo,
            hi: lim.hi,
            vmax: lim.vmax,
            amax: lim.amax,
            dt: lim.dt,
            p: start,
            v: [0.0; 6],
            clamped_cycles: 0,
        }
    }

    /// Restarts at rest at `start`.
    pub fn reset(&mut self, start: Pose6) {
        self.p = start;
        self.v = [0.0; 6];
    }

    /// The box (position and orientation): the workspace, or less of it
    /// where the controller's correction limits end sooner.
    pub fn set_box(&mut self, lo: Pose6, hi: Pose6) {
        self.lo = lo;
        self.hi = hi;
    }

    /// Follows a pose commanded past the filter (the way home, planned
    /// within tighter bounds): its step becomes the filter's velocity.
    pub fn track(&mut self, p: &Pose6) {
        for i in 0..6 {
            self.v[i] = (p[i] - self.p[i]) / self.dt;
            self.p[i] = p[i];
        }
    }

    /// The last pose let through.
    pub fn pose(&self) -> Pose6 {
        self.p
    }

    /// The last per-cycle velocity.
    pub fn velocity(&self) -> Pose6 {
        self.v
    }

    /// The next pose: `desired` if it is within every limit, otherwise the
    /// closest pose that is. Returns the pose and whether it was changed.
    pub fn filter(&mut self, desired: &Pose6) -> (Pose6, bool) {
        let mut changed = false;
        let dt = self.dt;
        for i in 0..6 {
            let u = self.amax[i] * dt;
            let vd = (desired[i] - self.p[i]) / dt;
            let vd = if vd.is_finite() { vd } else { 0.0 };
            let mut v = vd.clamp(self.v[i] - u, self.v[i] + u);
            v = v.clamp(-self.vmax[i], self.vmax[i]);
            let up = braking_speed(self.hi[i] - self.p[i], dt, u);
            let down = braking_speed(self.p[i] - self.lo[i], dt, u);
            v = v.clamp(-down, up);
            if (v - vd).abs() > 1e-9 * (1.0 + vd.abs()) {
                changed = true;
            }
            self.v[i] = v;
            self.p[i] += v * dt;
        }
        if changed {
            self.clamped_cycles += 1;
        }
        (self.p, changed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn braking_speed_inverts_the_stopping_distance() {
        let (dt, u) = (0.004, 0.1);
        for &d in &[0.0001, 0.003, 0.05, 0.4, 1.0] {
            let v = braking_speed(d, dt, u);
            let mut s = 0.0;
            let mut w = v;
            while w > 0.0 {
                s += w * dt;
                w -= u;
            }
            assert!((s - d).abs() < 1e-9, "d {d} s {s}");
        }
        assert_eq!(braking_speed(-1.0, dt, u), 0.0);
    }
}
