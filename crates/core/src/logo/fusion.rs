//! Fusion of the two spin sources: the logo and the trajectory (Magnus).
//!
//! They see different parts of ω. The trajectory's Magnus force
//! k_M ω × v is blind to the component along the velocity (sidespin about
//! the flight direction, "corkscrew"), but it is robust: no camera strip,
//! no logo that must face the camera. The logo sees all three components,
//! but only where the ball crosses the ceiling camera's strip, and its
//! rotation fit can alias (a rate off by whole half-turns per frame gap).
//!
//! Each source comes as a Gaussian (ω, Σ) and they are combined by their
//! inverse covariances (the information filter's update, which is also the
//! EKF's spin measurement update with H = I). Before that, a χ² gate on
//! the difference: a logo estimate inconsistent with the trajectory along
//! the directions the trajectory *does* see is an aliased or mis-detected
//! one, and is dropped rather than averaged in.

use nalgebra::Matrix3;

use crate::fit::TrajectoryFit;
use crate::logo::rotation::RotationFit;
use crate::physics::Vec3;

/// A spin estimate with its covariance, rad/s, one frame (table).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SpinEstimate {
    /// The spin ω, rad/s.
    pub spin: Vec3,
    /// Covariance of `spin`, (rad/s)².
    pub cov: Matrix3<f64>,
}

/// Floors on the logo's uncertainty: the rotation fit's residuals of a
/// clean sequence can be tiny, but the renderer's truth says the estimate
/// is rarely better than this (`topspin logo eval`).
pub(crate) const LOGO_MIN_RATE_STD: f64 = 1.5; // rad/s
pub(crate) const LOGO_MIN_AXIS_STD: f64 = 0.03; // rad

/// The largest 1σ we call "no information", rad/s.
pub(crate) const UNINFORMED_STD: f64 = 1e3;

/// χ² gate (3 dof, 99.9 %) on the difference of the two estimates.
pub(crate) const GATE_CHI2: f64 = 16.27;

impl SpinEstimate {
    /// The trajectory's spin from the refined fit of a flight: the weak
    /// axis (along the flight) with its data-only 1σ, the other two
    /// directions with the rest of the reported spread; `None` for the
    /// paper's fit, which reports no uncertainty.
    pub fn from_fit(f: &TrajectoryFit) -> Option<Self> {
        let (axis, weak_std) = f.weak_axis?;
        Some(Self::from_trajectory(f.spin, f.spin_std?, axis, weak_std))
    }

    fn from_trajectory(spin: Vec3, spin_std: Vec3, weak_axis: Vec3, weak_axis_std: f64) -> Self {
        let w = weak_axis.try_normalize(1e-12).unwrap_or_else(Vec3::x);
        let weak = if weak_axis_std.is_finite() { weak_axis_std.min(UNINFORMED_STD) } else { UNINFORMED_STD };
        let s2 = spin_std.norm_squared();
        let along = spin_std.dot(&w).powi(2);
        let perp = ((s2 - along).max(0.0) / 2.0).max(1e-4);
        let p = Matrix3::identity() - w * w.transpose();
        SpinEstimate { spin, cov: p * perp + w * w.transpose() * weak * weak }
    }

    /// The logo's spin: the rate's 1σ from the regression line's residual,
    /// the axis's from the positions' scatter about the fitted circle, both
    /// floored.
    pub fn from_rotation(fit: &RotationFit, t_span: f64) -> Self {
        let a = fit.axis.try_normalize(1e-12).unwrap_or_else(Vec3::z);
        let n = fit.seen.max(2) as f64;
        // A regression over n points spread uniformly over t_span:
        // σ_slope = σ / (t_span √(n/12)).
        let rate_std = (fit.rms_angle / (t_span.max(1e-3) * (n / 12.0).sqrt())).max(LOGO_MIN_RATE_STD);
        let radius = (1.0 - fit.plane_offset * fit.plane_offset).max(0.05).sqrt();
        let axis_std = (fit.rms_circle / (radius * n.sqrt())).max(LOGO_MIN_AXIS_STD);
        let tilt = (fit.rate.abs() * axis_std).max(LOGO_MIN_RATE_STD);
        let p = Matrix3::identity() - a * a.transpose();
        SpinEstimate { spin: fit.spin, cov: a * a.transpose() * rate_std * rate_std + p * tilt * tilt }
    }
}

/// What the fusion did.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Fused {
    /// Both combined.
    Both(SpinEstimate),
    /// The logo failed the gate: the trajectory alone (and the χ²).
    TrajectoryOnly(SpinEstimate, f64),
}

impl Fused {
    /// The resulting estimate, whichever way it was reached.
    pub fn estimate(&self) -> &SpinEstimate {
        match self {
            Fused::Both(e) | Fused::TrajectoryOnly(e, _) => e,
        }
    }
}

/// Combines the trajectory's and the logo's estimates (same frame).
pub fn fuse(trajectory: &SpinEstimate, logo: &SpinEstimate) -> Fused {
    let d = logo.spin - trajectory.spin;
    let s = trajectory.cov + logo.cov;
    let chi2 = s.try_inverse().map(|si| (d.transpose() * si * d)[0]).unwrap_or(f64::INFINITY);
    if chi2.is_nan() || chi2 > GATE_CHI2 {
        return Fused::TrajectoryOnly(*trajectory, chi2);
    }
    let (Some(it), Some(il)) = (trajectory.cov.try_inverse(), logo.cov.try_inverse()) else {
        return Fused::TrajectoryOnly(*trajectory, chi2);
    };
    let Some(cov) = (it + il).try_inverse() else {
        return Fused::TrajectoryOnly(*trajectory, chi2);
    };
    let spin = cov * (it * trajectory.spin + il * logo.spin);
    Fused::Both(SpinEstimate { spin, cov: (cov + cov.transpose()) * 0.5 })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn est(spin: Vec3, stds: [f64; 3]) -> SpinEstimate {
        SpinEstimate { spin, cov: Matrix3::from_diagonal(&Vec3::new(stds[0], stds[1], stds[2]).map(|s| s * s)) }
    }

    #[test]
    fn each_source_wins_where_it_sees() {
        // Trajectory blind along x (the flight), sharp in y, z; logo the
        // other way round.
        let truth = Vec3::new(40.0, -150.0, 20.0);
        let traj = est(Vec3::new(0.0, -151.0, 21.0), [UNINFORMED_STD, 2.0, 2.0]);
        let logo = est(Vec3::new(41.0, -140.0, 12.0), [2.0, 10.0, 10.0]);
        let Fused::Both(f) = fuse(&traj, &logo) else { panic!("gated") };
        assert!((f.spin - truth).norm() < (traj.spin - truth).norm());
        assert!((f.spin - truth).norm() < (logo.spin - truth).norm());
        assert!((f.spin.x - 41.0).abs() < 0.1 && (f.spin.y + 150.6).abs() < 0.5);
        // Never less certain than either.
        for i in 0..3 {
            assert!(f.cov[(i, i)] <= traj.cov[(i, i)] && f.cov[(i, i)] <= logo.cov[(i, i)]);
        }
    }

    #[test]
    fn an_aliased_logo_is_gated_out() {
        let traj = est(Vec3::new(0.0, -150.0, 20.0), [UNINFORMED_STD, 3.0, 3.0]);
        // Half the rate: an aliased rotation fit.
        let logo = est(Vec3::new(0.0, -75.0, 10.0), [2.0, 3.0, 3.0]);
        assert!(matches!(fuse(&traj, &logo), Fused::TrajectoryOnly(_, chi2) if chi2 > GATE_CHI2));
    }
}
