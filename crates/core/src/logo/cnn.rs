//! The logo network's contract (paper §III): a 60 × 60 crop in, the logo's
//! visibility and the ball's orientation out, and from those the logo's
//! centre on the unit sphere in the crop's view frame ([`super::view`]).
//!
//! The model is a single ONNX file written by `tools/logo_cnn/train.py`:
//! input `crops` f32 [N, 3, 60, 60] (RGB in [0, 1]), outputs `visibility`
//! [N] (probability) and `quaternion` [N, 4] (w, x, y, z, unit). The logo is
//! a circle, so the orientation is the *swing* from the view frame's +z
//! (towards the camera) onto the logo; the logo's direction is q·e_z·q⁻¹.
//!
//! The engine that runs the model (tract or ONNX Runtime through `ort`)
//! lives above the core, in `topspin-cnn`; the logo stream sees it only as
//! a [`LogoNetwork`].

use nalgebra::{Quaternion, UnitQuaternion};

use crate::calib::camera::CameraCalib;
use crate::logo::ball::Circle;
use crate::logo::rotation::LogoSample;
use crate::logo::view::BallView;
use crate::physics::Vec3;

/// Side of the network's input, px (the crops TTI1 carries).
pub const INPUT_SIZE: usize = 60;
/// Floats per crop.
pub const INPUT_LEN: usize = 3 * INPUT_SIZE * INPUT_SIZE;
/// Most crops per inference call (the paper's batch of 5).
pub const MAX_BATCH: usize = 5;
/// The default visibility threshold.
pub const VISIBLE_THRESHOLD: f32 = 0.5;

/// An engine that runs the logo network on crops.
///
/// Inference may allocate inside the engine, so it runs on the logo thread
/// only, never on a hot thread.
pub trait LogoNetwork: Send {
    /// The engine's name (for logs and `Debug`).
    fn engine_name(&self) -> &'static str;

    /// Runs crops (60 × 60 RGB8, row-major); `out[i]` is crop `i`'s
    /// answer. An error's message says what failed.
    fn infer_crops(&mut self, crops: &[&[u8]], out: &mut [CnnOutput]) -> Result<(), String>;
}

/// What the network says about one crop.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct CnnOutput {
    /// Probability that the logo's centre faces the camera.
    pub visibility: f32,
    /// The swing from the view frame's +z onto the logo.
    pub orientation: UnitQuaternion<f64>,
}

impl Default for CnnOutput {
    /// "No logo seen" (what a failed batch counts as).
    fn default() -> Self {
        CnnOutput { visibility: 0.0, orientation: UnitQuaternion::identity() }
    }
}

impl CnnOutput {
    /// The logo sample of a crop of capture time `t` (s) whose ball the
    /// camera side measured as `circle`: the logo's centre in the camera
    /// frame when the network sees it.
    pub fn sample(&self, cam: &CameraCalib, circle: Circle, t: f64) -> LogoSample {
        let pos = BallView::new(cam, circle.u, circle.v, circle.radius)
            .and_then(|v| self.seen(VISIBLE_THRESHOLD).map(|p| v.to_camera(&p)));
        LogoSample::new(t, pos)
    }

    /// The logo's centre on the unit sphere, view frame.
    pub fn logo_view(&self) -> Vec3 {
        self.orientation * Vec3::z()
    }

    /// The logo's centre when the network thinks it is seen.
    pub fn seen(&self, threshold: f32) -> Option<Vec3> {
        (self.visibility >= threshold).then(|| self.logo_view())
    }
}

/// Angle between two orientations, degrees, sign-aware (q ≡ −q).
pub fn geodesic_deg(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
    let d = a.coords.dot(&b.coords).abs().min(1.0);
    (2.0 * d.acos()).to_degrees()
}

/// The swing quaternion that turns +z onto the unit vector `logo` (the
/// network's target; undefined only for `logo` = −z, never visible).
pub fn swing_to(logo: &Vec3) -> UnitQuaternion<f64> {
    let q = Quaternion::new(1.0 + logo.z, -logo.y, logo.x, 0.0);
    UnitQuaternion::try_new(q, 1e-9)
        .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vec3::x_axis(), std::f64::consts::PI))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_swing_turns_z_onto_the_logo() {
        for v in
            [Vec3::new(0.3, -0.4, 0.8), Vec3::new(-0.9, 0.1, 0.2), Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.5, 0.5, -0.6)]
        {
            let v = v.normalize();
            let q = swing_to(&v);
            assert!((q * Vec3::z() - v).norm() < 1e-12, "{v:?}");
            let out = CnnOutput { visibility: 0.9, orientation: q };
            assert!((out.logo_view() - v).norm() < 1e-12);
            assert_eq!(out.seen(0.95), None);
        }
        let q = swing_to(&Vec3::new(0.0, 0.6, 0.8));
        let neg = UnitQuaternion::new_unchecked(-q.into_inner());
        assert!(geodesic_deg(&q, &neg) < 1e-6);
    }
}
