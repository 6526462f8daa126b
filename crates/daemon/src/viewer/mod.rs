//! The viewer: what Foxglove shows of the robot thinking — a 3D scene in
//! the table frame and time series — built on the telemetry thread from
//! the events it already receives, and sent to a live Foxglove WebSocket
//! server (`live`) and/or into the session recording (same channels, same
//! log times, so a recording and a live run look the same).
//!
//! Cold path only: everything here allocates and encodes; the hot threads
//! (ingest, estimator, RSI) only push their fixed-size `Copy` events into
//! their rings (`crate::runtime::telemetry`) and never wait for a viewer.
//!
//! # Channels
//!
//! Frames: `table` (the table frame T, the root) and `robot_base` (B), the
//! transform on `/tf`. Protobuf messages use Foxglove's well-known schemas
//! (the `foxglove` crate's); the plots are JSON with a JSON Schema.
//!
//! | topic | schema | what |
//! |---|---|---|
//! | `/view/cell` | `foxglove.SceneUpdate` | table, lines and net; robot base and workspace box (in `robot_base`); the hitting window (`hitting_window`: the hitting plane's, and the hitting volume's nearest plane's, fainter) — again every `CELL_INTERVAL_S` for clients that join later |
//! | `/tf` | `foxglove.FrameTransform` | `table` → `robot_base` |
//! | `/view/ball` | `foxglove.SceneUpdate` | each observation (`obs/<n>`, `OBS_LIFETIME_S`; cyan tracked, grey not tracked, red rejected by the EKF gate), the EKF estimate (`ekf`), the predicted path through the bounce to the hitting plane (`prediction`, with the crossing `hit`) after every observation, the spin arrow with its magnitude (`spin`), the logo direction (`logo`); these five expire `TRACK_LIFETIME_S` after their last update |
//! | `/view/robot` | `foxglove.SceneUpdate` | the planned bat (`bat_plan`: a disc at the hitting point, its velocity arrow); the arm from the forward kinematics of the actual joints (`arm_actual`, from `AIPos`: a cylinder per link, a sphere per joint and at the TCP, in `table`, metadata `ipoc`) and its ghost from the commanded joints (`arm_commanded`, from `ASPos`: translucent, ahead of the actual by the dead time and lag) (`viewer::arm`); the actual and commanded TCP (`tcp_actual`, `tcp_commanded`, bat discs in `robot_base`); the arm and TCP every `TCP_DECIMATION`th RSI cycle, expiring `ROBOT_LIFETIME_S` after their last update |
//! | `/view/plan_pose` | `foxglove.PoseInFrame` | the planned bat pose (`table`) |
//! | `/view/tcp` | `foxglove.PosesInFrame` | `[actual, commanded]` TCP (`robot_base`), every `TCP_DECIMATION`th RSI cycle |
//! | `/view/verdict` | `foxglove.SceneUpdate` | the demo only: hit or miss per ball at its true hitting point |
//! | `/plot/spin` | JSON | the EKF spin per observation: `trajectory`, `x_rps`, `y_rps`, `z_rps`, `norm_rps` |
//! | `/plot/prediction_error` | JSON | when a ball ends, per plan: `time_to_hit_s`, `error_mm` (hitting point), `dt_ms` (hitting time) against `reference` (`truth` in the demo, else the ball's last plan) |
//! | `/plot/rsi` | JSON | per RSI answer: `latency_us`, `controller_late` (the controller's count), `slow_answers`, `plans_late`, `plans_rejected` |
//! | `/plot/queues` | JSON | [`QueueDepths`](crate::runtime::QueueDepths) every `crate::runtime::telemetry::QUEUE_INTERVAL_S` |
//! | `/logo/crop` | `foxglove.RawImage` | the logo thread's crop (`rgb8`) |
//! | `/logo/fit` | `foxglove.ImageAnnotations` | on the crop: the ball (circle) and the detected logo (filled dot) |
//!
//! The logo thread (built elsewhere) feeds `/logo/*` by pushing a
//! [`LogoRecord`](crate::runtime::LogoRecord) into [`crate::runtime::daemon::Daemon::logo_tx`]; the
//! telemetry thread hands it to [`ViewerSink::logo`](sink::ViewerSink).
//!
//! Log times are wall clock: the monotonic time + `crate::clock::unix_offset_ns`.

pub(crate) mod arm;
pub(crate) mod live;
pub(crate) mod replay;
pub(crate) mod sink;

use foxglove::messages as fm;
use nalgebra::{Rotation3, UnitQuaternion};
use serde::Serialize;
use topspin_core::geometry::rot_zyx;

pub use live::LiveServer;
pub use replay::view_recording;
pub use sink::{DemoTruth, TrueHit, ViewerSink};

/// Where `--live` serves without an address (loopback, Foxglove's usual port).
pub const DEFAULT_LIVE_ADDR: &str = "127.0.0.1:8765";
/// Seconds between re-sends of the static cell scene and transform.
pub(crate) const CELL_INTERVAL_S: f64 = 1.0;
/// How long an observation stays in the scene, s.
pub(crate) const OBS_LIFETIME_S: f64 = 2.0;
/// How long the current ball's EKF estimate, prediction, hit, spin and logo
/// stay after their last update, s (then the scene is clear for the next).
pub(crate) const TRACK_LIFETIME_S: f64 = 0.5;
/// How long the arm and TCP entities of `/view/robot` stay after their
/// last update, s: they are refreshed every [`TCP_DECIMATION`] RSI cycles
/// (20 ms), so they vanish half a second after the controller goes silent
/// or stops sending their element.
pub(crate) const ROBOT_LIFETIME_S: f64 = 0.5;
/// One `/view/tcp` and TCP scene message every this many RSI cycles.
pub(crate) const TCP_DECIMATION: u64 = 5;
/// Spacing of the predicted path's points, s.
pub(crate) const PREDICTION_STEP_S: f64 = 0.01;
/// The longest predicted path, s.
pub(crate) const PREDICTION_HORIZON_S: f64 = 1.5;
/// Spin arrow length per revolution per second, m.
pub(crate) const SPIN_ARROW_M_PER_RPS: f64 = 0.004;

/// The parent frame: the table frame T.
pub(crate) const FRAME_TABLE: &str = "table";
/// The robot base frame B.
pub(crate) const FRAME_BASE: &str = "robot_base";

/// `/plot/spin`.
#[derive(Copy, Clone, Debug, Serialize)]
pub(crate) struct SpinPlot {
    pub trajectory: u32,
    pub x_rps: f64,
    pub y_rps: f64,
    pub z_rps: f64,
    pub norm_rps: f64,
}

/// `/plot/prediction_error`.
#[derive(Copy, Clone, Debug, Serialize)]
pub(crate) struct PredictionErrorPlot {
    pub trajectory: u32,
    pub seq: u32,
    pub time_to_hit_s: f64,
    pub error_mm: f64,
    pub dt_ms: f64,
    /// `truth` or `last plan`.
    pub reference: &'static str,
}

/// `/plot/rsi`.
#[derive(Copy, Clone, Debug, Default, Serialize)]
pub struct RsiPlot {
    /// The latest answer's latency (request arrival → answer sent), µs.
    pub latency_us: u64,
    /// The controller's latest count of late answers (`<Delay>`).
    pub controller_late: u64,
    /// Answers slower than the budget so far.
    pub slow_answers: u64,
    /// Plans taken although late so far.
    pub plans_late: u64,
    /// Plans refused so far.
    pub plans_rejected: u64,
}

/// A live server that cannot start.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// The WebSocket server could not bind or start.
    #[error("live view on {addr}: {message}")]
    Start {
        /// The address it was to serve on.
        addr: std::net::SocketAddr,
        /// Why it did not start.
        message: String,
    },
}

// Small geometry helpers (Foxglove's types from ours).

/// Foxglove's vector of `p`.
pub fn v3(p: topspin_core::physics::Vec3) -> fm::Vector3 {
    fm::Vector3 { x: p.x, y: p.y, z: p.z }
}

/// Foxglove's point at `p`.
pub fn p3(p: topspin_core::physics::Vec3) -> fm::Point3 {
    fm::Point3 { x: p.x, y: p.y, z: p.z }
}

/// Foxglove's colour of red, green, blue and alpha, each 0..=1.
pub fn color(r: f64, g: f64, b: f64, a: f64) -> fm::Color {
    fm::Color { r, g, b, a }
}

/// The identity rotation.
pub(crate) const IDENTITY: fm::Quaternion = fm::Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 };

fn qmul(p: fm::Quaternion, q: fm::Quaternion) -> fm::Quaternion {
    fm::Quaternion {
        w: p.w * q.w - p.x * q.x - p.y * q.y - p.z * q.z,
        x: p.w * q.x + p.x * q.w + p.y * q.z - p.z * q.y,
        y: p.w * q.y - p.x * q.z + p.y * q.w + p.z * q.x,
        z: p.w * q.z + p.x * q.y - p.y * q.x + p.z * q.w,
    }
}

/// Rotation of KUKA Euler angles Z-Y-X (rad), [`rot_zyx`] as a quaternion.
pub(crate) fn quat_zyx(a: f64, b: f64, c: f64) -> fm::Quaternion {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rot_zyx(a, b, c)));
    fm::Quaternion { x: q.i, y: q.j, z: q.k, w: q.w }
}

/// The rotation taking +x onto `d` (identity for a zero vector).
pub(crate) fn quat_x_to(d: topspin_core::physics::Vec3) -> fm::Quaternion {
    let n = d.norm();
    if !(n.is_finite() && n > 1e-12) {
        return IDENTITY;
    }
    let u = d / n;
    let w = 1.0 + u.x;
    if w < 1e-9 {
        // Opposite to +x: half a turn about z.
        return fm::Quaternion { x: 0.0, y: 0.0, z: 1.0, w: 0.0 };
    }
    // q = (1 + x·u, x × u) normalised; x × u = (0, −u.z, u.y).
    let (qx, qy, qz) = (0.0, -u.z, u.y);
    let norm = (w * w + qy * qy + qz * qz).sqrt();
    fm::Quaternion { x: qx / norm, y: qy / norm, z: qz / norm, w: w / norm }
}

/// The rotation taking +z onto `d` (a cylinder's axis; identity for a
/// zero vector): +z to +x (a quarter turn about y), then +x to `d`.
pub(crate) fn quat_z_to(d: topspin_core::physics::Vec3) -> fm::Quaternion {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    if !(d.norm().is_finite() && d.norm() > 1e-12) {
        return IDENTITY;
    }
    qmul(quat_x_to(d), fm::Quaternion { x: 0.0, y: h, z: 0.0, w: h })
}

/// A pose from a position and a rotation.
pub fn pose(p: topspin_core::physics::Vec3, q: fm::Quaternion) -> fm::Pose {
    fm::Pose { position: Some(v3(p)), orientation: Some(q) }
}

/// Foxglove's timestamp of `ns` since the Unix epoch.
pub fn stamp(ns: u64) -> fm::Timestamp {
    fm::Timestamp::new((ns / 1_000_000_000) as u32, (ns % 1_000_000_000) as u32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::channels::TOPICS;
    use topspin_core::physics::Vec3;

    /// `v` turned by `q`.
    pub(crate) fn rotate(q: fm::Quaternion, v: Vec3) -> Vec3 {
        let p = fm::Quaternion { x: v.x, y: v.y, z: v.z, w: 0.0 };
        let c = fm::Quaternion { x: -q.x, y: -q.y, z: -q.z, w: q.w };
        let r = qmul(qmul(q, p), c);
        Vec3::new(r.x, r.y, r.z)
    }

    #[test]
    fn x_goes_to_the_direction() {
        for d in [Vec3::new(0.0, 0.0, 2.0), Vec3::new(-1.0, 0.0, 0.0), Vec3::new(0.3, -0.4, 0.5), Vec3::x()] {
            let r = rotate(quat_x_to(d), Vec3::x());
            assert!((r - d.normalize()).norm() < 1e-12, "{d:?} → {r:?}");
        }
    }

    #[test]
    fn z_goes_to_the_direction() {
        for d in
            [Vec3::new(0.0, 0.0, 2.0), Vec3::new(0.0, 0.0, -1.0), Vec3::new(-1.0, 0.0, 0.0), Vec3::new(0.3, -0.4, 0.5)]
        {
            let r = rotate(quat_z_to(d), Vec3::z());
            assert!((r - d.normalize()).norm() < 1e-12, "{d:?} → {r:?}");
        }
        assert_eq!(quat_z_to(Vec3::zeros()), IDENTITY);
    }

    #[test]
    fn zyx_is_the_geometry_rotation() {
        let (a, b, c) = (0.3, -0.2, 1.1);
        let m = rot_zyx(a, b, c);
        let q = quat_zyx(a, b, c);
        for v in [Vec3::x(), Vec3::y(), Vec3::z()] {
            assert!((rotate(q, v) - m * v).norm() < 1e-12);
        }
    }

    /// Every topic the shipped layout names is one of ours.
    #[test]
    fn the_layout_names_our_topics() {
        fn strings(v: &serde_json::Value, out: &mut Vec<String>) {
            match v {
                serde_json::Value::String(s) => out.push(s.clone()),
                serde_json::Value::Array(a) => a.iter().for_each(|x| strings(x, out)),
                serde_json::Value::Object(o) => o.iter().for_each(|(k, x)| {
                    out.push(k.clone());
                    strings(x, out)
                }),
                _ => {}
            }
        }
        let layout: serde_json::Value =
            serde_json::from_str(include_str!("../../../../deploy/foxglove-layout.json")).expect("layout parses");
        let mut all = Vec::new();
        strings(&layout["configById"], &mut all);
        let topics: Vec<_> = all.iter().filter(|s| s.starts_with('/')).collect();
        assert!(topics.len() > 10);
        for t in topics {
            let topic = t.split(['.', '[']).next().unwrap();
            assert!(TOPICS.iter().any(|k| k.name() == topic), "the layout names {t}");
        }
    }

    #[test]
    fn every_topic_has_a_schema_and_a_distinct_name() {
        let mut names: Vec<_> = TOPICS.iter().map(|t| t.name()).collect();
        for (k, t) in TOPICS.iter().enumerate() {
            assert_eq!(*t as usize, k);
            let s = t.schema();
            assert!(!s.data.is_empty());
            assert_eq!(s.encoding, if t.encoding() == "json" { "jsonschema" } else { "protobuf" });
            if t.encoding() == "json" {
                let _: serde_json::Value = serde_json::from_slice(&s.data).expect("JSON schema parses");
            }
        }
        names.sort();
        names.dedup();
        assert_eq!(names.len(), TOPICS.len());
    }
}
