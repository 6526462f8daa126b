//! The correction a committed stroke takes when its hitting pose moves: a
//! quintic per axis, added to the stroke's Ruckig trajectory, from the
//! correction's own state now (position, velocity, acceleration: zero for
//! the first) to the change of the hitting joints and joint velocity at the
//! hitting time, with no acceleration left there.
//!
//! Why not re-plan with Ruckig: near the hit the axes of a time-synchronised
//! stroke are in their final, limit-bound motion towards a non-zero
//! velocity, and for such a target an exact duration often lies in one of
//! Ruckig's blocked intervals: a millimetre's refinement 60 ms before the
//! hit comes back 20–200 ms late. A blend of that millimetre needs a few
//! per cent of the axes' acceleration; the generator checks the sum
//! against the limits before it takes one ([`crate::motion::generator`]).
//!
//! Plain arithmetic on fixed arrays: no allocation, no clock.

use crate::kinematics::AXES;

/// Per-axis state: position, velocity, acceleration.
pub(crate) type AxisState = [[f64; AXES]; 3];

/// Six quintics over `[t0, t0 + duration]`, in the generator's seconds.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Blend {
    t0: f64,
    duration: f64,
    /// Coefficients of τ⁰ … τ⁵ (τ = t − t0) per axis.
    c: [[f64; 6]; AXES],
}

impl Blend {
    /// From `start` (x, v, a) at `t0` to position `x1` and velocity `v1`
    /// with zero acceleration at `t0 + duration`; `None` for a duration
    /// that is not positive or values that are not finite.
    pub(crate) fn new(t0: f64, duration: f64, start: &AxisState, x1: &[f64; AXES], v1: &[f64; AXES]) -> Option<Self> {
        if !(duration > 0.0 && t0.is_finite()) {
            return None;
        }
        let t = duration;
        let mut c = [[0.0; 6]; AXES];
        for i in 0..AXES {
            let (x0, v0, a0) = (start[0][i], start[1][i], start[2][i]);
            let dx = x1[i] - x0;
            c[i] = [
                x0,
                v0,
                0.5 * a0,
                (20.0 * dx - (8.0 * v1[i] + 12.0 * v0) * t - 3.0 * a0 * t * t) / (2.0 * t.powi(3)),
                (-30.0 * dx + (14.0 * v1[i] + 16.0 * v0) * t + 3.0 * a0 * t * t) / (2.0 * t.powi(4)),
                (12.0 * dx - 6.0 * (v1[i] + v0) * t - a0 * t * t) / (2.0 * t.powi(5)),
            ];
        }
        c.iter().flatten().all(|x| x.is_finite()).then_some(Blend { t0, duration, c })
    }

    /// When the blend ends (the hitting time), s.
    pub(crate) fn end(&self) -> f64 {
        self.t0 + self.duration
    }

    /// The blend at `t`: before its start, its start; after its end, its
    /// end position moving on at its end velocity.
    pub(crate) fn at(&self, t: f64) -> AxisState {
        let tau = (t - self.t0).clamp(0.0, self.duration);
        let beyond = (t - self.end()).max(0.0);
        let mut s = [[0.0; AXES]; 3];
        for (i, c) in self.c.iter().enumerate() {
            let x = c[0] + tau * (c[1] + tau * (c[2] + tau * (c[3] + tau * (c[4] + tau * c[5]))));
            let v = c[1] + tau * (2.0 * c[2] + tau * (3.0 * c[3] + tau * (4.0 * c[4] + tau * 5.0 * c[5])));
            let a = 2.0 * c[2] + tau * (6.0 * c[3] + tau * (12.0 * c[4] + tau * 20.0 * c[5]));
            s[0][i] = x + v * beyond;
            s[1][i] = v;
            s[2][i] = if beyond > 0.0 { 0.0 } else { a };
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn meets_both_ends_exactly() {
        let start =
            [[0.1, -0.2, 0.0, 0.3, 0.0, -0.05], [0.5, 0.0, -1.0, 0.2, 0.1, 0.0], [2.0, -3.0, 0.0, 1.0, 0.0, 4.0]];
        let x1 = [0.12, -0.19, 0.01, 0.31, -0.02, -0.04];
        let v1 = [0.4, 0.1, -0.9, 0.0, 0.2, 0.05];
        let b = Blend::new(10.0, 0.08, &start, &x1, &v1).unwrap();
        let s0 = b.at(10.0);
        let s1 = b.at(10.08);
        for i in 0..AXES {
            for k in 0..3 {
                assert!((s0[k][i] - start[k][i]).abs() < 1e-9, "start {k} {i}");
            }
            assert!((s1[0][i] - x1[i]).abs() < 1e-9 && (s1[1][i] - v1[i]).abs() < 1e-9 && s1[2][i].abs() < 1e-6);
        }
    }

    #[test]
    fn velocity_and_acceleration_are_the_derivatives() {
        let start = [[0.0; AXES], [0.3; AXES], [-1.0; AXES]];
        let b = Blend::new(0.0, 0.05, &start, &[0.004; AXES], &[0.2; AXES]).unwrap();
        let h = 1e-6;
        for t in [0.005, 0.02, 0.049] {
            let (m, p) = (b.at(t - h), b.at(t + h));
            let s = b.at(t);
            assert!(((p[0][0] - m[0][0]) / (2.0 * h) - s[1][0]).abs() < 1e-5);
            assert!(((p[1][0] - m[1][0]) / (2.0 * h) - s[2][0]).abs() < 1e-3);
        }
        // Beyond its end it moves on at the end velocity.
        let e = b.at(0.06);
        assert!((e[0][0] - (0.004 + 0.2 * 0.01)).abs() < 1e-9, "{e:?}");
        assert!((e[1][0] - 0.2).abs() < 1e-9 && e[2][0] == 0.0, "{e:?}");
    }

    #[test]
    fn refuses_what_it_cannot_be() {
        let z = [[0.0; AXES]; 3];
        assert!(Blend::new(0.0, 0.0, &z, &[0.0; AXES], &[0.0; AXES]).is_none());
        assert!(Blend::new(0.0, 0.05, &z, &[f64::NAN; AXES], &[0.0; AXES]).is_none());
    }
}
