//! How a flight moves with what it started from: the sensitivities Φ of a
//! ball's position and velocity to its initial position, velocity and spin
//! and to the logarithms of its drag and lift multipliers, integrated with
//! the flight (the variational equations, to second order per step). For
//! the Gauss–Newton fits over a window of samples (`fit::refine`, the
//! estimator's batches): one trajectory gives the Jacobian that forward
//! differences need N + 1 trajectories for.

use std::ops::{AddAssign, SubAssign};

use nalgebra::SMatrix;

use super::{BallState, FlightModel, Propagator};

/// Φ for `N` unknowns: columns 0–2 the initial position, 3–5 the initial
/// velocity, 6–8 the spin (constant in flight), and where given the
/// natural logarithms of the drag's and the lift's multipliers.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Sensitivities<const N: usize> {
    /// ∂position/∂unknowns.
    pub pos: SMatrix<f64, 3, N>,
    /// ∂velocity/∂unknowns.
    pub vel: SMatrix<f64, 3, N>,
    drag: Option<usize>,
    lift: Option<usize>,
}

impl<const N: usize> Sensitivities<N> {
    /// At the flight's start: the identity on position and velocity; `drag`
    /// and `lift` name the columns of the multipliers' logarithms, if any.
    pub fn new(drag: Option<usize>, lift: Option<usize>) -> Self {
        const { assert!(N >= 9, "position, velocity and spin take 9 columns") };
        let mut pos = SMatrix::<f64, 3, N>::zeros();
        let mut vel = SMatrix::<f64, 3, N>::zeros();
        for k in 0..3 {
            pos[(k, k)] = 1.0;
            vel[(k, k + 3)] = 1.0;
        }
        Sensitivities { pos, vel, drag, lift }
    }

    /// Advances Φ by `h` from the flight's state `s` at the step's start
    /// under `f` (the caller advances `s`): d/dt Φ_p = Φ_v; d/dt Φ_v =
    /// ∂a/∂v Φ_v + [0 0 ∂a/∂ω ∂a/∂ln m_D ∂a/∂ln m_L], with ∂a/∂ln m_D =
    /// −k_D‖v‖v (the drag itself) and ∂a/∂ln m_L = k_M ω×v (the lift).
    pub fn step(&mut self, f: &FlightModel, s: &BallState, h: f64) {
        let (dadv, dadw) = f.accel_jacobians(&s.vel, &s.spin);
        let mut dv = dadv * self.vel;
        dv.fixed_view_mut::<3, 3>(0, 6).add_assign(&dadw);
        if let Some(k) = self.drag {
            dv.column_mut(k).sub_assign(&(s.vel * (f.k_d() * s.vel.norm())));
        }
        if let Some(k) = self.lift {
            dv.column_mut(k).add_assign(&(s.spin.cross(&s.vel) * f.k_m(&s.vel, &s.spin)));
        }
        self.pos += self.vel * h + dv * (0.5 * h * h);
        self.vel += dv * h;
    }

    /// Flies `s` on by `span` s under `prop` (RK4, equal steps of at most
    /// `max_step`) and Φ with it.
    pub fn fly(&mut self, prop: &Propagator, s: &mut BallState, span: f64, max_step: f64) {
        if span <= 0.0 {
            return;
        }
        let n = (span / max_step).ceil().max(1.0);
        let h = span / n;
        for _ in 0..n as usize {
            self.step(&prop.flight, s, h);
            *s = prop.rk4(s, h);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;
    use crate::physics::{FlightScales, Vec3};

    /// Φ after 0.3 s of a fast topspin flight against forward differences
    /// of the flight itself, within 1 % (the Jacobian at each step's start:
    /// 0.3 % off here for the largest columns). A Gauss–Newton fit needs no more: its answer is set
    /// by the residuals, Φ only steers; a wrong or missing term is off by
    /// its whole size.
    #[test]
    fn sensitivities_match_forward_differences() {
        let prop = Calibration::default_cell().propagator();
        let start =
            BallState::new(Vec3::new(-1.8, 0.1, 0.35), Vec3::new(5.5, -0.2, 0.9), Vec3::new(20.0, 550.0, -40.0));
        let fly = |x: &[f64; 11]| {
            let scales = FlightScales { drag: x[9].exp(), lift: x[10].exp() };
            let p = Propagator { flight: prop.flight.scaled(scales), ..prop };
            let s =
                BallState::new(Vec3::new(x[0], x[1], x[2]), Vec3::new(x[3], x[4], x[5]), Vec3::new(x[6], x[7], x[8]));
            p.fly(&s, 0.3)
        };
        let x0: [f64; 11] = [-1.8, 0.1, 0.35, 5.5, -0.2, 0.9, 20.0, 550.0, -40.0, 0.0, 0.0];
        let mut phi = Sensitivities::<11>::new(Some(9), Some(10));
        let mut s = start;
        phi.fly(&prop, &mut s, 0.3, 0.3 / 75.0);
        let end = fly(&x0);
        let differences: Vec<_> = (0..11)
            .map(|j| {
                let d = if (6..9).contains(&j) { 1e-2 } else { 1e-6 };
                let mut x = x0;
                x[j] += d;
                let moved = fly(&x);
                ((moved.pos - end.pos) / d, (moved.vel - end.vel) / d)
            })
            .collect();
        // Each column against its group's size (the start's position and
        // velocity, the spin, the multipliers): the spin along the flight
        // moves the ball 40 times less than the spin across it.
        for group in [0..6, 6..9, 9..11] {
            let scale = group.clone().map(|j| differences[j].0.norm().max(differences[j].1.norm())).fold(0.0, f64::max);
            for j in group {
                let (dp, dv) = differences[j];
                assert!(
                    (phi.pos.column(j) - dp).norm() < 1e-2 * scale,
                    "position column {j}: {} vs {dp}",
                    phi.pos.column(j)
                );
                assert!(
                    (phi.vel.column(j) - dv).norm() < 1e-2 * scale,
                    "velocity column {j}: {} vs {dv}",
                    phi.vel.column(j)
                );
            }
        }
    }
}
