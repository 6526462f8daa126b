//! The ceiling camera's calibration (`calib/camera.toml`): pinhole
//! intrinsics, the read-out region of interest, the pose in the table frame
//! T, frame rate and exposure, and the ball's printed logo.
//!
//! Standalone for now: [`CameraCalib::parse`] reads a `camera.toml` text (the
//! daemon reads the file, or takes [`DEFAULT_CAMERA`]). Frames: the camera frame C has x
//! along image u (right), y along image v (down) and z along the optical
//! axis; pixel centres lie at integer coordinates of the full sensor.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

use crate::calib::CalibError;
use crate::physics::Vec3;

/// The compiled-in default (the repository's `calib/camera.toml`).
/// The repository's `calib/camera.toml`, compiled in.
pub const DEFAULT_CAMERA: &str = include_str!("../../../../calib/camera.toml");

/// `[camera]` of `calib/camera.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSection {
    /// Sensor width, px.
    pub width: u32,
    /// Sensor height, px.
    pub height: u32,
    /// Pixel pitch, µm.
    pub pixel_pitch_um: f64,
    /// Lens focal length, mm.
    pub focal_length_mm: f64,
    /// Principal point (u, v), px.
    pub principal_point: [f64; 2],
    /// Read-out region: x0, y0, width, height, px.
    pub roi: [u32; 4],
    /// Optical centre in the table frame, m.
    pub position: [f64; 3],
    /// Mounting error after the nominal downward pose: yaw, pitch, roll
    /// about the camera's z, y, x axes, degrees.
    pub mount_ypr_deg: [f64; 3],
    /// Frames per second.
    pub frame_rate_hz: f64,
    /// Exposure time, s.
    pub exposure_s: f64,
}

/// `[logo]` of `calib/camera.toml`: the ball as the logo method sees it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogoSection {
    /// Radius of the circular printed logo, m.
    pub radius_m: f64,
    /// Radius of the ball, m.
    pub ball_radius_m: f64,
}

/// `calib/camera.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct CameraFile {
    pub version: u32,
    pub camera: CameraSection,
    pub logo: LogoSection,
}

/// The ceiling camera, loaded and validated.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraCalib {
    /// The `[camera]` section as loaded.
    pub camera: CameraSection,
    /// The `[logo]` section as loaded.
    pub logo: LogoSection,
    /// Focal length in px (same in u and v: square pixels).
    pub f_px: f64,
    /// Rotation taking camera-frame vectors into the table frame (R_TC).
    pub table_from_camera: Rotation3<f64>,
}

impl CameraCalib {
    /// The compiled-in camera (the repository's `calib/camera.toml`).
    pub fn default_camera() -> Self {
        Self::parse(DEFAULT_CAMERA, Path::new("<default>/camera.toml")).expect("compiled-in camera is valid (tested)")
    }

    /// Parses and validates the text of a `camera.toml`.
    pub fn parse(text: &str, path: &Path) -> Result<Self, CalibError> {
        let file: CameraFile = toml::from_str(text).map_err(|e| CalibError::Parse {
            path: path.to_owned(),
            message: e.message().to_owned() + &e.span().map(|s| format!(" (at byte {})", s.start)).unwrap_or_default(),
        })?;
        let c = &file.camera;
        let l = &file.logo;
        let bad = |key: &'static str, value: f64| CalibError::OutOfRange { path: PathBuf::from(path), key, value };
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !(1..=16384).contains(&c.width) {
            return Err(bad("camera.width", c.width as f64));
        }
        if !(1..=16384).contains(&c.height) {
            return Err(bad("camera.height", c.height as f64));
        }
        let checks = [
            ("camera.pixel_pitch_um", c.pixel_pitch_um, pos(c.pixel_pitch_um) && c.pixel_pitch_um < 100.0),
            ("camera.focal_length_mm", c.focal_length_mm, pos(c.focal_length_mm) && c.focal_length_mm < 1000.0),
            ("camera.principal_point", c.principal_point[0], c.principal_point.iter().all(|p| p.is_finite())),
            ("camera.frame_rate_hz", c.frame_rate_hz, pos(c.frame_rate_hz) && c.frame_rate_hz <= 100_000.0),
            ("camera.exposure_s", c.exposure_s, pos(c.exposure_s) && c.exposure_s * c.frame_rate_hz <= 1.0),
            ("camera.position", c.position[2], c.position.iter().all(|p| p.is_finite()) && c.position[2] > 0.5),
            (
                "camera.mount_ypr_deg",
                c.mount_ypr_deg[0],
                c.mount_ypr_deg.iter().all(|a| a.is_finite() && a.abs() <= 30.0),
            ),
            ("logo.ball_radius_m", l.ball_radius_m, pos(l.ball_radius_m) && l.ball_radius_m < 0.1),
            ("logo.radius_m", l.radius_m, pos(l.radius_m) && l.radius_m < 0.9 * l.ball_radius_m),
        ];
        for (key, value, ok) in checks {
            if !ok {
                return Err(bad(key, value));
            }
        }
        let [x0, y0, w, h] = c.roi;
        if w == 0 || h == 0 || x0.saturating_add(w) > c.width || y0.saturating_add(h) > c.height {
            return Err(bad("camera.roi", w as f64));
        }
        // Nominal: x_C = +x_T, y_C = −y_T, z_C = −z_T (columns of R_TC).
        let nominal = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, -1.0, 0.0),
            Vector3::new(0.0, 0.0, -1.0),
        ]));
        let [yaw, pitch, roll] = c.mount_ypr_deg.map(f64::to_radians);
        let mount = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), pitch)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), roll);
        let f_px = c.focal_length_mm / (c.pixel_pitch_um * 1e-3);
        Ok(CameraCalib { camera: file.camera, logo: file.logo, f_px, table_from_camera: nominal * mount })
    }

    /// Principal point (cx, cy), px.
    pub(crate) fn principal_point(&self) -> (f64, f64) {
        (self.camera.principal_point[0], self.camera.principal_point[1])
    }

    /// Optical centre in the table frame, m.
    pub fn position(&self) -> Vec3 {
        Vec3::from(self.camera.position)
    }

    /// A table-frame point in the camera frame.
    pub fn to_camera(&self, p_table: &Vec3) -> Vec3 {
        self.table_from_camera.inverse_transform_vector(&(p_table - self.position()))
    }

    /// A camera-frame vector rotated into the table frame.
    pub fn vector_to_table(&self, v_camera: &Vec3) -> Vec3 {
        self.table_from_camera * v_camera
    }

    /// The pixel (u, v) a camera-frame point projects to, or `None` behind
    /// the camera.
    pub(crate) fn project(&self, p_camera: &Vec3) -> Option<(f64, f64)> {
        if p_camera.z <= 1e-9 {
            return None;
        }
        let (cx, cy) = self.principal_point();
        Some((cx + self.f_px * p_camera.x / p_camera.z, cy + self.f_px * p_camera.y / p_camera.z))
    }

    /// The unit ray (camera frame) through pixel (u, v).
    pub fn ray(&self, u: f64, v: f64) -> Vec3 {
        let (cx, cy) = self.principal_point();
        Vec3::new((u - cx) / self.f_px, (v - cy) / self.f_px, 1.0).normalize()
    }

    /// True when the w × h pixel block at (x0, y0) lies inside the ROI.
    pub fn block_in_roi(&self, x0: i64, y0: i64, w: u32, h: u32) -> bool {
        let [rx, ry, rw, rh] = self.camera.roi.map(i64::from);
        x0 >= rx && y0 >= ry && x0 + i64::from(w) <= rx + rw && y0 + i64::from(h) <= ry + rh
    }

    /// The logo's angular radius on the ball, rad (logo radius / ball radius).
    pub fn logo_angular_radius(&self) -> f64 {
        self.logo.radius_m / self.logo.ball_radius_m
    }

    /// Seconds between frames.
    pub fn frame_period(&self) -> f64 {
        1.0 / self.camera.frame_rate_hz
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compiled_default_loads_and_looks_down() {
        let c = CameraCalib::default_camera();
        assert!((c.f_px - 2730.4).abs() < 0.1, "{}", c.f_px);
        // The optical axis points (nearly) down the table's −z.
        let axis = c.vector_to_table(&Vec3::z());
        assert!(axis.z < -0.99, "{axis:?}");
        // Image u runs along +x.
        assert!(c.vector_to_table(&Vec3::x()).x > 0.99);
        // The table centre projects near the principal point, a ball at the
        // centre 0.25 m up has a radius of about 23 px.
        let p = c.to_camera(&Vec3::new(0.0, 0.0, 0.25));
        let (u, v) = c.project(&p).unwrap();
        assert!((u - 959.5).abs() < 50.0 && (v - 599.5).abs() < 50.0, "{u} {v}");
        let r = c.f_px * 0.02 / p.norm();
        assert!((22.0..25.0).contains(&r), "{r}");
        let ray = c.ray(u, v);
        assert!((ray - p.normalize()).norm() < 1e-9);
        assert!(c.block_in_roi(900, 570, 60, 60));
        assert!(!c.block_in_roi(900, 350, 60, 60));
    }

    #[test]
    fn a_bad_value_is_named() {
        let text = DEFAULT_CAMERA.replace("exposure_s = 0.00025", "exposure_s = -1.0");
        let e = CameraCalib::parse(&text, Path::new("x/camera.toml")).unwrap_err().to_string();
        assert!(e.contains("camera.exposure_s"), "{e}");
        let text = DEFAULT_CAMERA.replace("roi = [0, 400, 1920, 400]", "roi = [0, 900, 1920, 400]");
        let e = CameraCalib::parse(&text, Path::new("x/camera.toml")).unwrap_err().to_string();
        assert!(e.contains("camera.roi"), "{e}");
    }
}
