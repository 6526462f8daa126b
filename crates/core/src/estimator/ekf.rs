//! The extended Kalman filter over position, velocity and spin (9 states)
//! in the table frame. Prediction integrates the flight model (RK4) and
//! handles a table bounce inside the step by splitting it at the impact;
//! the covariance follows the linearised flight and bounce maps. Updates
//! take a position observation with Mahalanobis gating. Joseph-form
//! update and explicit symmetrisation keep the covariance symmetric
//! positive definite. Fixed-size matrices: nothing allocates.
//!
//! Spin is a state (not a parameter from the polynomial fit) because the
//! paper's cubic is biased by its own approximation of the flight while the
//! filter uses the model itself; measured in `topspin eval stream`.

use nalgebra::{Matrix3, SMatrix, SVector};

use crate::physics::{BallState, Event, Propagator, StopAt, Vec3};

/// A 9×9 matrix over the filter state (position, velocity, spin), such as
/// its covariance.
pub(crate) type M9 = SMatrix<f64, 9, 9>;
pub(crate) type V9 = SVector<f64, 9>;

/// Longest step of the covariance propagation, s.
pub(crate) const COV_STEP: f64 = 0.01;

/// χ² (3 dof) at 99.9 %: observations farther than this are rejected.
pub(crate) const GATE_CHI2: f64 = 16.27;

/// Noise settings.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct EkfNoise {
    /// Per-axis position measurement σ, m.
    pub measurement: f64,
    /// White acceleration noise spectral density, (m/s²)²·s.
    pub accel: f64,
    /// Spin random walk, (rad/s)²/s.
    pub spin: f64,
    /// Extra velocity variance at a bounce, per axis, (m/s)²: what the
    /// bounce model leaves unexplained (a session learns it,
    /// `super::session`).
    pub bounce_vel: Vec3,
    /// Extra spin variance at a bounce, (rad/s)².
    pub bounce_spin: f64,
    /// σ of the spin's size just before a bounce, as a share of it, added
    /// along the spin before the contact: a flight read through a lift
    /// that saturates cannot tell a fast spin from a medium one, and the
    /// bounce can (its kick). The first samples after the bounce then move
    /// the velocity as far as that spin's kick is uncertain. 0 by default;
    /// a session learning the spin sets it per ball
    /// ([`super::spin_prior::SpinPrior::share_at`]).
    pub bounce_spin_share: f64,
}

impl Default for EkfNoise {
    fn default() -> Self {
        EkfNoise {
            measurement: 0.002,
            accel: 0.005,
            spin: 1.0,
            bounce_vel: Vec3::repeat(0.05),
            bounce_spin: 400.0,
            bounce_spin_share: 0.0,
        }
    }
}

/// The outcome of offering an observation to the filter.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Update {
    /// Accepted; the squared Mahalanobis distance.
    Accepted {
        /// Squared Mahalanobis distance of the innovation.
        d2: f64,
    },
    /// Rejected by the gate.
    Rejected {
        /// Squared Mahalanobis distance of the innovation.
        d2: f64,
    },
}

/// The filter: state, covariance and the time they hold at (s).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Ekf {
    /// Time the state and covariance hold at, s.
    pub t: f64,
    /// State: position (m), velocity (m/s) and spin (rad/s) in the table
    /// frame T, in that order.
    pub x: V9,
    /// Covariance of `x`.
    pub p: M9,
    /// Process and measurement noise.
    pub noise: EkfNoise,
    /// Bounces on the robot's half (x > 0) passed since initialisation.
    pub bounces: u32,
    /// Bounces on the opponent's half passed (a serve's on its own half).
    pub own_half_bounces: u32,
    /// The state at the latest bounce's contact, just before the impact.
    pub last_contact: Option<BallState>,
    /// The variance of each velocity component just after that impact
    /// from the state's uncertainty before it (through the bounce's
    /// Jacobian), before [`EkfNoise::bounce_vel`] is added.
    pub contact_vel_var: Vec3,
    /// The same from the flight's own reading alone (before
    /// [`EkfNoise::bounce_spin_share`] is added): what the spin prior
    /// weighs one kick with.
    pub contact_vel_var_read: Vec3,
}

fn state_of(x: &V9) -> BallState {
    BallState::new(Vec3::new(x[0], x[1], x[2]), Vec3::new(x[3], x[4], x[5]), Vec3::new(x[6], x[7], x[8]))
}

fn vec_of(s: &BallState) -> V9 {
    V9::from_iterator(s.pos.iter().chain(s.vel.iter()).chain(s.spin.iter()).copied())
}

impl Ekf {
    /// A filter at `state` (time `t`) with per-block standard deviations.
    pub fn new(t: f64, state: &BallState, pos_std: f64, vel_std: f64, spin_std: f64, noise: EkfNoise) -> Self {
        let mut p = M9::zeros();
        for k in 0..3 {
            p[(k, k)] = pos_std * pos_std;
            p[(k + 3, k + 3)] = vel_std * vel_std;
            p[(k + 6, k + 6)] = spin_std * spin_std;
        }
        Ekf {
            t,
            x: vec_of(state),
            p,
            noise,
            bounces: 0,
            own_half_bounces: 0,
            last_contact: None,
            contact_vel_var: Vec3::zeros(),
            contact_vel_var_read: Vec3::zeros(),
        }
    }

    /// The state `x` as a ball state.
    pub fn state(&self) -> BallState {
        state_of(&self.x)
    }

    /// Replaces the spin's covariance with `cov` (symmetric positive
    /// definite), keeping the filter's correlations of the spin with the
    /// position and velocity in whitened form: P ← T P Tᵀ with T the
    /// identity on position and velocity and A = L_new L_old⁻¹ on the spin
    /// (L the Cholesky factors), so P stays a covariance. Unchanged where
    /// either block is not positive definite.
    pub fn set_spin_covariance(&mut self, cov: &Matrix3<f64>) {
        let old = self.p.fixed_view::<3, 3>(6, 6).into_owned();
        let (Some(l_old), Some(l_new)) = (old.cholesky(), cov.cholesky()) else { return };
        let Some(l_old_inv) = l_old.l().try_inverse() else { return };
        let cross = l_new.l() * l_old_inv * self.p.fixed_view::<3, 6>(6, 0);
        if !(cross.iter().all(|v| v.is_finite())) {
            return;
        }
        self.p.fixed_view_mut::<3, 6>(6, 0).copy_from(&cross);
        self.p.fixed_view_mut::<6, 3>(0, 6).copy_from(&cross.transpose());
        self.p.fixed_view_mut::<3, 3>(6, 6).copy_from(&((cov + cov.transpose()) * 0.5));
    }

    /// Continuous-time Jacobian F of the flight at `s`.
    fn jacobian(prop: &Propagator, s: &BallState) -> M9 {
        let (dadv, dadw) = prop.flight.accel_jacobians(&s.vel, &s.spin);
        let mut jac = M9::zeros();
        jac.fixed_view_mut::<3, 3>(0, 3).copy_from(&Matrix3::identity());
        jac.fixed_view_mut::<3, 3>(3, 3).copy_from(&dadv);
        jac.fixed_view_mut::<3, 3>(3, 6).copy_from(&dadw);
        jac
    }

    /// Flight over `dt` from the current state: covariance by the
    /// second-order transition I + F dt + (F dt)²/2 at the step's middle.
    fn fly(&mut self, prop: &Propagator, dt: f64) {
        if dt <= 0.0 {
            return;
        }
        let s0 = self.state();
        let mid = prop.rk4(&s0, 0.5 * dt);
        let fdt = Self::jacobian(prop, &mid) * dt;
        let phi = M9::identity() + fdt + fdt * fdt * 0.5;
        let q = &self.noise;
        let mut qm = M9::zeros();
        for k in 0..3 {
            qm[(k, k)] = q.accel * dt * dt * dt / 3.0;
            qm[(k, k + 3)] = q.accel * dt * dt / 2.0;
            qm[(k + 3, k)] = q.accel * dt * dt / 2.0;
            qm[(k + 3, k + 3)] = q.accel * dt;
            qm[(k + 6, k + 6)] = q.spin * dt;
        }
        self.p = phi * self.p * phi.transpose() + qm;
    }

    /// The bounce's linear map (α held fixed) on velocity and spin.
    fn bounce_jacobian(prop: &Propagator, before: &BallState) -> M9 {
        let b = &prop.bounce;
        let a = b.alpha(&before.vel, &before.spin);
        // The contact meets m·ω and hands back ω⁺/m (m the table's spin
        // scale): ∂v⁺/∂ω scales by m, ∂ω⁺/∂v by 1/m.
        let (m, r) = (b.spin_scale, b.radius);
        let mut j = M9::identity();
        let k = 1.5 * a / (r * m);
        let ar = a * r * m;
        #[rustfmt::skip]
        let block = SMatrix::<f64, 6, 6>::from_row_slice(&[
            1.0 - a, 0.0, 0.0,            0.0, ar, 0.0,
            0.0, 1.0 - a, 0.0,            -ar, 0.0, 0.0,
            0.0, 0.0, -b.restitution,     0.0, 0.0, 0.0,
            0.0, -k, 0.0,                 1.0 - 1.5 * a, 0.0, 0.0,
            k, 0.0, 0.0,                  0.0, 1.0 - 1.5 * a, 0.0,
            0.0, 0.0, 0.0,                0.0, 0.0, 1.0,
        ]);
        j.fixed_view_mut::<6, 6>(3, 3).copy_from(&block);
        j
    }

    /// Predicts to time `t` (≥ the filter's time), through a bounce if one
    /// happens on the way. Returns the bounce time if there was one on the
    /// robot's half (a serve's bounce on its own half is counted apart).
    pub fn predict(&mut self, prop: &Propagator, t: f64) -> Option<f64> {
        let mut bounced = None;
        let mut guard = 0;
        while self.t < t && guard < 4 {
            guard += 1;
            let mut s = self.state();
            let mut now = self.t;
            let event = prop.advance(&mut s, &mut now, &StopAt::time(t));
            let dt = now - self.t;
            // Covariance over the flight part, in steps of at most COV_STEP
            // (the transition is second order in F·dt, and ‖F‖·COV_STEP ≈ 0.01).
            let steps = (dt / COV_STEP).ceil().max(1.0) as usize;
            let mut cov_state = *self;
            for _ in 0..steps {
                let h = dt / steps as f64;
                cov_state.fly(prop, h);
                cov_state.x = vec_of(&prop.rk4(&cov_state.state(), h));
            }
            self.p = cov_state.p;
            self.x = vec_of(&s);
            self.t = now;
            match event {
                Event::Bounce { t: tb, before } => {
                    let w = before.spin;
                    let j = Self::bounce_jacobian(prop, &before);
                    let vel_var = |p: &M9| Vec3::new(p[(3, 3)], p[(4, 4)], p[(5, 5)]);
                    let read = j * self.p * j.transpose();
                    self.contact_vel_var_read = vel_var(&read);
                    // A spin whose size is uncertain by the share beyond
                    // the filter's own reading: its kick moves the
                    // velocity after the contact, and the first samples
                    // after it tell how far.
                    let share = self.noise.bounce_spin_share;
                    if share > 0.0 {
                        let mut spin_cov = self.p.fixed_view_mut::<3, 3>(6, 6);
                        spin_cov += w * w.transpose() * (share * share);
                        self.p = j * self.p * j.transpose();
                    } else {
                        self.p = read;
                    }
                    self.contact_vel_var = vel_var(&self.p);
                    for k in 3..6 {
                        self.p[(k, k)] += self.noise.bounce_vel[k - 3];
                        self.p[(k + 3, k + 3)] += self.noise.bounce_spin;
                    }
                    self.last_contact = Some(before);
                    if before.pos.x > 0.0 {
                        self.bounces += 1;
                        bounced = Some(tb);
                    } else {
                        self.own_half_bounces += 1;
                    }
                }
                Event::TimeLimit { .. } => break,
                // Net, floor: the state stops there; the caller ends the track.
                _ => {
                    self.t = t;
                    break;
                }
            }
        }
        self.symmetrise();
        bounced
    }

    /// Offers a position observation at the filter's time; updates unless
    /// gated out.
    pub fn update(&mut self, z: &Vec3) -> Update {
        let r = self.noise.measurement * self.noise.measurement;
        let y = z - Vec3::new(self.x[0], self.x[1], self.x[2]);
        let s = self.p.fixed_view::<3, 3>(0, 0).into_owned() + Matrix3::identity() * r;
        let Some(s_inv) = s.try_inverse() else {
            return Update::Rejected { d2: f64::INFINITY };
        };
        let d2 = (y.transpose() * s_inv * y)[0];
        if !(d2.is_finite() && d2 <= GATE_CHI2) {
            return Update::Rejected { d2 };
        }
        // K = P Hᵀ S⁻¹ with H = [I 0 0]
        let k: SMatrix<f64, 9, 3> = self.p.fixed_view::<9, 3>(0, 0).into_owned() * s_inv;
        self.x += k * y;
        // Joseph form: (I − KH) P (I − KH)ᵀ + K R Kᵀ
        let mut ikh = M9::identity();
        ikh.fixed_view_mut::<9, 3>(0, 0).sub_assign(&k);
        self.p = ikh * self.p * ikh.transpose() + k * k.transpose() * r;
        self.symmetrise();
        Update::Accepted { d2 }
    }

    /// Offers a direct measurement of the spin (the logo's, rad/s) with
    /// covariance `r`: the information from the logo fused with what the
    /// trajectory taught the filter, unless the χ² gate says the two
    /// disagree (an aliased or mis-detected logo).
    pub(crate) fn update_spin(&mut self, z: &Vec3, r: &Matrix3<f64>) -> Update {
        let y = z - Vec3::new(self.x[6], self.x[7], self.x[8]);
        let s = self.p.fixed_view::<3, 3>(6, 6).into_owned() + r;
        let Some(s_inv) = s.try_inverse() else {
            return Update::Rejected { d2: f64::INFINITY };
        };
        let d2 = (y.transpose() * s_inv * y)[0];
        if !(d2.is_finite() && d2 <= GATE_CHI2) {
            return Update::Rejected { d2 };
        }
        // K = P Hᵀ S⁻¹ with H = [0 0 I]
        let k: SMatrix<f64, 9, 3> = self.p.fixed_view::<9, 3>(0, 6).into_owned() * s_inv;
        self.x += k * y;
        let mut ikh = M9::identity();
        ikh.fixed_view_mut::<9, 3>(0, 6).sub_assign(&k);
        self.p = ikh * self.p * ikh.transpose() + k * r * k.transpose();
        self.symmetrise();
        Update::Accepted { d2 }
    }

    fn symmetrise(&mut self) {
        self.p = (self.p + self.p.transpose()) * 0.5;
    }
}

use std::ops::SubAssign;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;
    use proptest::prelude::*;

    fn is_spd(p: &M9) -> bool {
        (p - p.transpose()).abs().max() <= 1e-9 * p.abs().max() && p.cholesky().is_some()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn covariance_stays_symmetric_positive_definite(
            vx in 3.0..12.0f64, vz in -1.0..2.0f64, wy in -600.0..600.0f64, wz in -300.0..300.0f64,
            noise in prop::collection::vec((-0.01..0.01f64, -0.01..0.01f64, -0.01..0.01f64), 60),
            outlier_every in 3usize..20,
        ) {
            let prop = Calibration::default_cell().propagator();
            let truth0 = BallState::new(Vec3::new(-1.5, 0.0, 0.3), Vec3::new(vx, 0.1, vz), Vec3::new(0.0, wy, wz));
            let mut ekf = Ekf::new(0.0, &truth0, 0.01, 0.5, 200.0, EkfNoise::default());
            let mut truth = truth0;
            let mut t = 0.0;
            for (i, (nx, ny, nz)) in noise.iter().enumerate() {
                let mut tt = t;
                let _ = prop.advance(&mut truth, &mut tt, &StopAt::time(t + 1.0 / 150.0));
                t += 1.0 / 150.0;
                ekf.predict(&prop, t);
                prop_assert!(is_spd(&ekf.p), "after predict {i}");
                let mut z = truth.pos + Vec3::new(*nx, *ny, *nz);
                if i % outlier_every == 0 { z.x += 0.3; }
                ekf.update(&z);
                prop_assert!(is_spd(&ekf.p), "after update {i}");
            }
        }
    }

    /// A filter that has run a while: correlated blocks throughout.
    fn run_filter() -> Ekf {
        let prop = Calibration::default_cell().propagator();
        let truth = BallState::new(Vec3::new(-1.5, 0.0, 0.3), Vec3::new(6.0, 0.1, 0.8), Vec3::new(0.0, 300.0, 20.0));
        let mut ekf = Ekf::new(0.0, &truth, 0.01, 0.5, 200.0, EkfNoise::default());
        for i in 1..20 {
            let t = i as f64 / 150.0;
            ekf.predict(&prop, t);
            ekf.update(&prop.fly(&truth, t).pos);
        }
        ekf
    }

    /// The spin's block becomes the one given; position and velocity keep
    /// theirs, and their correlation with the spin keeps its form.
    #[test]
    fn the_spin_covariance_is_replaced_and_the_rest_kept() {
        let mut ekf = run_filter();
        let before = ekf.p;
        let cov = Matrix3::new(25.0, 3.0, -1.0, 3.0, 100.0, 5.0, -1.0, 5.0, 16.0);
        ekf.set_spin_covariance(&cov);
        let p = &ekf.p;
        assert!((p.fixed_view::<3, 3>(6, 6) - cov).abs().max() < 1e-9, "{p}");
        assert_eq!(p.fixed_view::<6, 6>(0, 0), before.fixed_view::<6, 6>(0, 0));
        assert!(is_spd(p));
        // Whitened, the cross-covariance is the same: L⁻¹ P_sx on both sides.
        let whiten = |m: &M9| {
            let l = m.fixed_view::<3, 3>(6, 6).into_owned().cholesky().unwrap().l();
            l.try_inverse().unwrap() * m.fixed_view::<3, 6>(6, 0)
        };
        assert!((whiten(p) - whiten(&before)).abs().max() < 1e-9 * whiten(&before).abs().max());
        // Not a covariance: nothing changes.
        let mut kept = ekf;
        kept.set_spin_covariance(&Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0));
        assert_eq!(kept.p, ekf.p);
    }

    #[test]
    fn tracks_through_a_bounce() {
        let prop = Calibration::default_cell().propagator();
        let truth0 = BallState::new(Vec3::new(-1.5, 0.0, 0.3), Vec3::new(7.0, 0.1, 0.8), Vec3::new(0.0, 200.0, 0.0));
        let mut ekf = Ekf::new(0.0, &truth0, 0.01, 0.3, 150.0, EkfNoise::default());
        ekf.x[7] = 0.0; // spin unknown at the start
        let mut truth = truth0;
        let mut t = 0.0;
        let mut bounces = 0;
        for _ in 0..75 {
            let target = t + 1.0 / 150.0;
            loop {
                if let Event::TimeLimit { .. } = prop.advance(&mut truth, &mut t, &StopAt::time(target)) {
                    break;
                }
            }
            if ekf.predict(&prop, t).is_some() {
                bounces += 1;
            }
            assert!(matches!(ekf.update(&truth.pos), Update::Accepted { .. }));
        }
        assert_eq!(bounces, 1);
        assert!((ekf.state().pos - truth.pos).norm() < 0.002);
        assert!((ekf.state().vel - truth.vel).norm() < 0.05);
    }
}
