//! The ball as one crop sees it (paper §II-C, made exact for a pinhole
//! camera off its optical axis).
//!
//! The paper divides a pixel's offset from the ball's centre by the ball's
//! radius and takes z = √(1 − x² − y²). That assumes the camera looks at
//! the ball along its optical axis; at the ROI's ends the line of sight is
//! 19° off axis and the ball's image is an ellipse 6 % longer radially. So
//! we do the same in the ball's **view frame** V: e₃ points from the ball
//! to the camera, e₁ along image u (orthogonalised), e₂ = e₃ × e₁ (image up);
//! a 2 × 2 map M takes pixel offsets to (x, y) in units of the ball's
//! radius, scaled so that the ball's image has the measured area π r².
//! A visible surface point is (x, y, √(1 − x² − y²)) in V; the camera-frame
//! vector is [e₁ e₂ e₃] times that.

use nalgebra::Matrix3;

use crate::calib::camera::CameraCalib;
use crate::physics::Vec3;

/// The view frame and pixel map of one crop.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BallView {
    /// Ball centre column in full-sensor pixels.
    pub u: f64,
    /// Ball centre row in full-sensor pixels.
    pub v: f64,
    /// Radius of the circle with the ball image's area, px.
    pub radius: f64,
    /// Columns e₁, e₂, e₃ in the camera frame (camera ← view).
    pub camera_from_view: Matrix3<f64>,
    /// Pixel offset (du, dv) → (x, y) in ball radii: row-major 2 × 2.
    pub m: [f64; 4],
    /// The inverse map, (x, y) → (du, dv).
    pub m_inv: [f64; 4],
}

impl BallView {
    /// The view of a ball centred at pixel (u, v) with radius `radius` px,
    /// or `None` for a non-positive or non-finite circle.
    pub fn new(cam: &CameraCalib, u: f64, v: f64, radius: f64) -> Option<BallView> {
        if !(u.is_finite() && v.is_finite() && radius.is_finite() && radius > 0.5) {
            return None;
        }
        let (cx, cy) = cam.principal_point();
        let f = cam.f_px;
        let d = Vec3::new((u - cx) / f, (v - cy) / f, 1.0);
        let dn = d.norm();
        let c = d / dn;
        let e3 = -c;
        let e1 = (Vec3::x() - c * c.x).normalize();
        let e2 = e3.cross(&e1);
        // ∂ĉ/∂u = (I − ĉĉᵀ)(1/f, 0, 0)/|d|; e₁, e₂ ⟂ ĉ.
        let m0 = [e1.x / (f * dn), e1.y / (f * dn), e2.x / (f * dn), e2.y / (f * dn)];
        let det0 = (m0[0] * m0[3] - m0[1] * m0[2]).abs();
        if det0 <= 0.0 || !det0.is_finite() {
            return None;
        }
        let s = 1.0 / (det0.sqrt() * radius);
        let m = m0.map(|x| x * s);
        let det = m[0] * m[3] - m[1] * m[2];
        let m_inv = [m[3] / det, -m[1] / det, -m[2] / det, m[0] / det];
        Some(BallView { u, v, radius, camera_from_view: Matrix3::from_columns(&[e1, e2, e3]), m, m_inv })
    }

    /// Pixel offset from the centre → (x, y) in ball radii (view frame).
    #[inline]
    pub fn to_disc(&self, du: f64, dv: f64) -> (f64, f64) {
        (self.m[0] * du + self.m[1] * dv, self.m[2] * du + self.m[3] * dv)
    }

    /// (x, y) in ball radii → pixel offset from the centre.
    #[inline]
    pub(crate) fn disc_to_pixel_offset(&self, x: f64, y: f64) -> (f64, f64) {
        (self.m_inv[0] * x + self.m_inv[1] * y, self.m_inv[2] * x + self.m_inv[3] * y)
    }

    /// A view-frame vector in the camera frame.
    pub fn to_camera(&self, v: &Vec3) -> Vec3 {
        self.camera_from_view * v
    }

    /// A camera-frame vector in the view frame.
    pub fn to_view(&self, v: &Vec3) -> Vec3 {
        self.camera_from_view.transpose() * v
    }

    /// The true view of a ball centred at `p_camera` (m, camera frame) with
    /// radius `r` m: the projected centre and the radius of the circle with
    /// the area of its (elliptical) image. `None` behind the camera.
    pub fn of_sphere(cam: &CameraCalib, p_camera: &Vec3, r: f64) -> Option<BallView> {
        let (u, v) = cam.project(p_camera)?;
        let dist = p_camera.norm();
        if dist <= r {
            return None;
        }
        // The silhouette is the cone of half-angle α (sin α = r/D) around
        // the line of sight: the circle of radius sin α in the unscaled
        // tangent map M₀, whose image has area π sin²α / |det M₀|.
        let (cx, cy) = cam.principal_point();
        let f = cam.f_px;
        let d = Vec3::new((u - cx) / f, (v - cy) / f, 1.0);
        let dn = d.norm();
        let c = d / dn;
        let e1 = (Vec3::x() - c * c.x).normalize();
        let e2 = (-c).cross(&e1);
        let det0 = ((e1.x * e2.y - e1.y * e2.x) / (f * f * dn * dn)).abs();
        let radius = (r / dist) / det0.sqrt();
        BallView::new(cam, u, v, radius)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn on_axis_it_is_the_papers_projection() {
        let mut cam = CameraCalib::default_camera();
        cam.camera.principal_point = [1000.0, 600.0];
        let v = BallView::new(&cam, 1000.0, 600.0, 20.0).unwrap();
        let (x, y) = v.to_disc(10.0, 0.0);
        assert!((x - 0.5).abs() < 1e-9 && y.abs() < 1e-9);
        // Image down is view −y.
        let (x, y) = v.to_disc(0.0, 10.0);
        assert!(x.abs() < 1e-9 && (y + 0.5).abs() < 1e-9);
        let (du, dv) = v.disc_to_pixel_offset(0.3, -0.2);
        assert!((du - 6.0).abs() < 1e-9 && (dv - 4.0).abs() < 1e-9);
        // e₃ points back at the camera.
        assert!((v.to_camera(&Vec3::z()) - Vec3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
    }

    #[test]
    fn off_axis_the_ball_is_stretched_radially() {
        let cam = CameraCalib::default_camera();
        // A ball 0.8 m along x from the axis, 2.35 m away.
        let p = Vec3::new(0.8, 0.0, 2.3);
        let view = BallView::of_sphere(&cam, &p, 0.02).unwrap();
        // Along u (radial) one ball radius is more pixels than across.
        let (du, _) = view.disc_to_pixel_offset(1.0, 0.0);
        let (_, dv) = view.disc_to_pixel_offset(0.0, 1.0);
        assert!(du.abs() > dv.abs() * 1.04, "{du} {dv}");
        // The silhouette edge at view x = 1 is where the ray grazes the sphere.
        let u_edge = view.u + du;
        let ray = cam.ray(u_edge, view.v);
        let closest = p - ray * ray.dot(&p);
        assert!((closest.norm() - 0.02).abs() < 2e-4, "{}", closest.norm());
    }
}
