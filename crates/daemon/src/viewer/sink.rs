//! [`ViewerSink`]: the telemetry thread's sink that builds the viewer's
//! messages (see the module doc of [`crate::viewer`]) and sends them to the
//! live server and into the recording; the recording's own channels are
//! passed on unchanged.

use std::collections::VecDeque;
use std::sync::{Arc, OnceLock};

use foxglove::Encode;
use foxglove::messages as fm;
use serde::Serialize;

use super::arm::{self, ArmView};
use super::{
    CELL_INTERVAL_S, FRAME_BASE, FRAME_TABLE, IDENTITY, LiveServer, OBS_LIFETIME_S, PREDICTION_HORIZON_S,
    PREDICTION_STEP_S, PredictionErrorPlot, ROBOT_LIFETIME_S, RsiPlot, SPIN_ARROW_M_PER_RPS, SpinPlot, TCP_DECIMATION,
    TRACK_LIFETIME_S, color, p3, pose, quat_x_to, quat_zyx, stamp, v3,
};
use crate::channels::{TOPICS, Topic};
use crate::record::sink::RecordingSink;
use crate::runtime::telemetry::{
    DatagramRecord, LOGO_CROP_SIDE, LogoRecord, QueueDepths, RsiRecord, Telemetry, TelemetrySink,
};
use topspin_core::calib::Calibration;
use topspin_core::estimator::EstimatorEvent;
use topspin_core::kinematics::Joints;
use topspin_core::physics::{BallState, Propagator, Vec3, rad_to_rps};
use topspin_core::physics::{Event, StopAt};
use topspin_core::plan::StrikePlan;
use topspin_core::rsi::SessionEvent;
use topspin_core::rsi::{KukaPose, RobFrame, SenFrame};
use topspin_core::time::{Duration, Instant};

/// A bat's orientation with its z axis turned onto its x axis (a quarter
/// turn about y): the cylinder drawn for the bat lies along z, the face's
/// normal along x.
fn face_axis(q: fm::Quaternion) -> fm::Quaternion {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    super::qmul(q, fm::Quaternion { x: 0.0, y: h, z: 0.0, w: h })
}

/// Ball radius drawn, m.
const BALL_RADIUS: f64 = 0.02;
/// Bat disc radius drawn, m.
const BAT_RADIUS: f64 = 0.075;
/// Actual-TCP samples kept for the demo's verdicts (RSI cycles).
const TCP_TRAIL: usize = 512;

/// One ball's true hitting-plane crossing (the demo knows it).
#[derive(Copy, Clone, Debug)]
pub struct TrueHit {
    /// The ball's index in the demo.
    pub ball: usize,
    /// When it crosses, on the daemon's clock.
    pub t: Instant,
    /// Where it crosses, table frame, m.
    pub pos: Vec3,
    /// Its velocity there, table frame, m/s.
    pub vel: Vec3,
    /// Inside the hitting window.
    pub reachable: bool,
}

/// The demo's ground truth, set once its start time is known.
pub type DemoTruth = Arc<OnceLock<Vec<TrueHit>>>;

/// Where the messages go.
struct Outputs {
    live: Option<LiveServer>,
    recording: Option<RecordingSink>,
    offset: u64,
    buf: Vec<u8>,
    sent: u64,
    /// The last log time sent on each topic ([`TOPICS`] order).
    last_log: [u64; TOPICS.len()],
}

impl Outputs {
    fn wants(&self, topic: Topic) -> bool {
        self.recording.is_some() || self.live.as_ref().is_some_and(|l| l.wants(topic))
    }

    fn wall(&self, t: Instant) -> u64 {
        t.as_nanos() + self.offset
    }

    /// The log time of a message about `at` on `topic`: its wall time, held
    /// back from running backwards. One topic carries events stamped on
    /// different threads' clocks (`/view/robot`: plans at their making, TCP
    /// at the RSI request), which reach the telemetry thread out of order.
    fn log_time(&mut self, topic: Topic, at: Instant) -> u64 {
        let wall = self.wall(at);
        let last = &mut self.last_log[topic as usize];
        *last = (*last).max(wall);
        *last
    }

    fn emit(&mut self, topic: Topic, log_time: u64) {
        if let Some(l) = self.live.as_ref() {
            l.send(topic, &self.buf, log_time);
        }
        if let Some(r) = self.recording.as_mut() {
            r.view(topic, &self.buf, log_time);
        }
        self.sent += 1;
    }

    fn proto<T: Encode>(&mut self, topic: Topic, msg: &T, at: Instant) {
        if !self.wants(topic) {
            return;
        }
        self.buf.clear();
        if msg.encode(&mut self.buf).is_ok() {
            let t = self.log_time(topic, at);
            self.emit(topic, t);
        }
    }

    fn json<T: Serialize>(&mut self, topic: Topic, msg: &T, at: Instant) {
        if !self.wants(topic) {
            return;
        }
        self.buf.clear();
        if serde_json::to_writer(&mut self.buf, msg).is_ok() {
            let t = self.log_time(topic, at);
            self.emit(topic, t);
        }
    }
}

/// What the viewer remembers of the current ball.
#[derive(Debug, Default)]
struct CurrentBall {
    trajectory: Option<u32>,
    /// Plans of the current trajectory: (made_at, hit_time, position, seq).
    plans: Vec<StrikePlan>,
    /// Capture time (s) of the latest observation the EKF gate rejected.
    rejected_t: Option<f64>,
    last_pos: Option<Vec3>,
}

/// The telemetry sink behind the live view and the recording's viewer channels.
pub struct ViewerSink {
    cal: Calibration,
    arm: ArmView,
    prop: Propagator,
    out: Outputs,
    ball: CurrentBall,
    obs_count: u64,
    rsi_count: u64,
    rsi: RsiPlot,
    /// The RSI start pose (first `RIst`), for the commanded TCP.
    start_pose: Option<KukaPose>,
    /// Actual TCP in T, by request arrival.
    trail: VecDeque<(Instant, Vec3)>,
    truth: Option<DemoTruth>,
    judged: usize,
    next_cell: Option<Instant>,
}

impl std::fmt::Debug for ViewerSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ViewerSink")
            .field("live", &self.out.live)
            .field("recording", &self.out.recording.is_some())
            .field("sent", &self.out.sent)
            .finish_non_exhaustive()
    }
}

impl ViewerSink {
    /// A sink for the live server and/or the recording (its own channels
    /// and the viewer's); `truth`: the demo's, for the hit/miss verdicts.
    pub fn new(
        cal: &Calibration,
        live: Option<LiveServer>,
        recording: Option<RecordingSink>,
        truth: Option<DemoTruth>,
    ) -> Self {
        ViewerSink {
            cal: cal.clone(),
            arm: ArmView::new(&cal.robot),
            prop: cal.propagator(),
            out: Outputs {
                live,
                recording,
                offset: crate::clock::unix_offset_ns(),
                buf: Vec::new(),
                sent: 0,
                last_log: [0; TOPICS.len()],
            },
            ball: CurrentBall::default(),
            obs_count: 0,
            rsi_count: 0,
            rsi: RsiPlot::default(),
            start_pose: None,
            trail: VecDeque::with_capacity(TCP_TRAIL),
            truth,
            judged: 0,
            next_cell: None,
        }
    }

    /// Log times = monotonic + `offset` (a replay uses its recording's).
    pub fn with_offset(mut self, offset: u64) -> Self {
        self.out.offset = offset;
        self
    }

    /// Viewer messages sent so far (to the live server and/or recording).
    pub fn sent(&self) -> u64 {
        self.out.sent
    }

    /// The static cell: table, net, robot base, workspace, hitting window; and `/tf`.
    fn cell(&mut self, at: Instant) {
        let ts = Some(stamp(self.out.wall(at)));
        let t = &self.cal.table;
        let (hl, hw) = (t.length / 2.0, t.width / 2.0);
        let white = color(1.0, 1.0, 1.0, 1.0);
        let table = fm::SceneEntity {
            timestamp: ts,
            frame_id: FRAME_TABLE.into(),
            id: "table".into(),
            cubes: vec![
                fm::CubePrimitive {
                    pose: Some(pose(Vec3::new(0.0, 0.0, -0.015), IDENTITY)),
                    size: Some(v3(Vec3::new(t.length, t.width, 0.03))),
                    color: Some(color(0.05, 0.2, 0.45, 1.0)),
                },
                fm::CubePrimitive {
                    pose: Some(pose(Vec3::new(0.0, 0.0, t.net_height / 2.0), IDENTITY)),
                    size: Some(v3(Vec3::new(0.004, t.net_length, t.net_height))),
                    color: Some(color(0.9, 0.9, 0.9, 0.5)),
                },
            ],
            lines: vec![fm::LinePrimitive {
                r#type: fm::line_primitive::Type::LineList as i32,
                pose: Some(pose(Vec3::zeros(), IDENTITY)),
                thickness: 0.02,
                points: [
                    (-hl, -hw, hl, -hw),
                    (hl, -hw, hl, hw),
                    (hl, hw, -hl, hw),
                    (-hl, hw, -hl, -hw),
                    (-hl, 0.0, hl, 0.0),
                ]
                .iter()
                .flat_map(|&(x0, y0, x1, y1)| [p3(Vec3::new(x0, y0, 0.001)), p3(Vec3::new(x1, y1, 0.001))])
                .collect(),
                color: Some(white),
                ..Default::default()
            }],
            ..Default::default()
        };
        let ws = &self.cal.robot.workspace;
        let lo = Vec3::from(ws.min_xyz_m);
        let hi = Vec3::from(ws.max_xyz_m);
        let robot = fm::SceneEntity {
            timestamp: ts,
            frame_id: FRAME_BASE.into(),
            id: "robot".into(),
            cubes: vec![
                fm::CubePrimitive {
                    pose: Some(pose((lo + hi) / 2.0, IDENTITY)),
                    size: Some(v3(hi - lo)),
                    color: Some(color(0.2, 0.8, 0.3, 0.12)),
                },
                fm::CubePrimitive {
                    pose: Some(pose(Vec3::new(0.0, 0.0, 0.1), IDENTITY)),
                    size: Some(v3(Vec3::new(0.25, 0.25, 0.2))),
                    color: Some(color(1.0, 0.45, 0.0, 1.0)),
                },
            ],
            texts: vec![fm::TextPrimitive {
                pose: Some(pose(Vec3::new(0.0, 0.0, 0.3), IDENTITY)),
                billboard: true,
                font_size: 14.0,
                scale_invariant: true,
                color: Some(white),
                text: self.cal.robot.robot.model.clone(),
            }],
            ..Default::default()
        };
        let s = &self.cal.strike;
        // The hitting plane's window, and the hitting volume's nearest
        // plane with its own (narrower) window, when there is a volume.
        let outline = |x: f64, y: [f64; 2], alpha: f64| fm::LinePrimitive {
            r#type: fm::line_primitive::Type::LineLoop as i32,
            pose: Some(pose(Vec3::zeros(), IDENTITY)),
            thickness: 0.005,
            points: vec![
                p3(Vec3::new(x, y[0], s.window_z[0])),
                p3(Vec3::new(x, y[1], s.window_z[0])),
                p3(Vec3::new(x, y[1], s.window_z[1])),
                p3(Vec3::new(x, y[0], s.window_z[1])),
            ],
            color: Some(color(1.0, 0.9, 0.1, alpha)),
            ..Default::default()
        };
        let mut lines = vec![outline(s.hit_plane_x, s.window_y, 1.0)];
        let near = s.depth()[0];
        if near < s.hit_plane_x {
            lines.push(outline(near, s.hit_depth_window_y.unwrap_or(s.window_y), 0.5));
        }
        let window = fm::SceneEntity {
            timestamp: ts,
            frame_id: FRAME_TABLE.into(),
            id: "hitting_window".into(),
            lines,
            ..Default::default()
        };
        self.out.proto(Topic::Cell, &fm::SceneUpdate { deletions: vec![], entities: vec![table, robot, window] }, at);
        let base = &self.cal.robot.cell;
        let yaw = self.cal.robot.base_yaw();
        let tf = fm::FrameTransform {
            timestamp: ts,
            parent_frame_id: FRAME_TABLE.into(),
            child_frame_id: FRAME_BASE.into(),
            translation: Some(v3(Vec3::from(base.base_in_table_xyz_m))),
            rotation: Some(quat_zyx(yaw, 0.0, 0.0)),
        };
        self.out.proto(Topic::Tf, &tf, at);
    }

    fn tick(&mut self, at: Instant) {
        if self.next_cell.is_none_or(|n| at >= n) {
            self.next_cell = Some(at + Duration::from_nanos((CELL_INTERVAL_S * 1e9) as u64));
            self.cell(at);
        }
    }

    /// An entity of the current ball (EKF estimate, prediction, hit, spin,
    /// logo): refreshed with every observation, gone [`TRACK_LIFETIME_S`]
    /// after the last, so nothing of one ball stays on screen for the next.
    fn tracked(&self, at: Instant, id: &str) -> fm::SceneEntity {
        fm::SceneEntity {
            lifetime: Some(fm::Duration::saturating_from_secs_f64(TRACK_LIFETIME_S)),
            ..self.entity(at, FRAME_TABLE, id)
        }
    }

    fn entity(&self, at: Instant, frame: &str, id: &str) -> fm::SceneEntity {
        fm::SceneEntity {
            timestamp: Some(stamp(self.out.wall(at))),
            frame_id: frame.into(),
            id: id.into(),
            ..Default::default()
        }
    }

    fn observed(&mut self, capture: Instant, pos: Vec3, track: Option<(u32, BallState)>) {
        self.obs_count += 1;
        let new_trajectory = track.map(|(id, _)| id);
        if new_trajectory.is_some() && new_trajectory != self.ball.trajectory {
            self.end_ball(capture);
            self.ball.trajectory = new_trajectory;
        }
        if !self.out.wants(Topic::Ball) && !self.out.wants(Topic::Spin) {
            return;
        }
        let rejected = self.ball.rejected_t == Some(capture.as_secs_f64());
        let c = match (rejected, track.is_some()) {
            (true, _) => color(1.0, 0.1, 0.1, 1.0),
            (false, true) => color(0.2, 0.9, 1.0, 0.9),
            (false, false) => color(0.6, 0.6, 0.6, 0.7),
        };
        let mut obs = self.entity(capture, FRAME_TABLE, &format!("obs/{}", self.obs_count));
        obs.lifetime = Some(fm::Duration::saturating_from_secs_f64(OBS_LIFETIME_S));
        obs.spheres.push(fm::SpherePrimitive {
            pose: Some(pose(pos, IDENTITY)),
            size: Some(v3(Vec3::repeat(BALL_RADIUS * 1.2))),
            color: Some(c),
        });
        let mut entities = vec![obs];
        if let Some((trajectory, state)) = track {
            self.ball.last_pos = Some(state.pos);
            let mut ekf = self.tracked(capture, "ekf");
            ekf.spheres.push(fm::SpherePrimitive {
                pose: Some(pose(state.pos, IDENTITY)),
                size: Some(v3(Vec3::repeat(2.0 * BALL_RADIUS))),
                color: Some(color(1.0, 0.55, 0.0, 1.0)),
            });
            entities.push(ekf);
            entities.extend(self.prediction(capture, &state));
            let rps = state.spin.map(rad_to_rps);
            let mut spin = self.tracked(capture, "spin");
            let len = (rps.norm() * SPIN_ARROW_M_PER_RPS).clamp(0.0, 0.5);
            spin.arrows.push(fm::ArrowPrimitive {
                pose: Some(pose(state.pos, quat_x_to(state.spin))),
                shaft_length: len * 0.8,
                shaft_diameter: 0.006,
                head_length: len * 0.2,
                head_diameter: 0.015,
                color: Some(color(0.9, 0.2, 0.9, 1.0)),
            });
            spin.texts.push(fm::TextPrimitive {
                pose: Some(pose(state.pos + Vec3::new(0.0, 0.0, 0.08), IDENTITY)),
                billboard: true,
                font_size: 14.0,
                scale_invariant: true,
                color: Some(color(0.9, 0.2, 0.9, 1.0)),
                text: format!("{:.0} rps", rps.norm()),
            });
            entities.push(spin);
            let plot = SpinPlot { trajectory, x_rps: rps.x, y_rps: rps.y, z_rps: rps.z, norm_rps: rps.norm() };
            self.out.json(Topic::Spin, &plot, capture);
        }
        self.out.proto(Topic::Ball, &fm::SceneUpdate { deletions: vec![], entities }, capture);
    }

    /// The predicted path from `state` through the bounce to the hitting plane.
    fn prediction(&self, at: Instant, state: &BallState) -> Vec<fm::SceneEntity> {
        let mut s = *state;
        let t0 = at.as_secs_f64();
        let mut t = t0;
        let mut points = vec![p3(s.pos)];
        let mut crossing = None;
        while t < t0 + PREDICTION_HORIZON_S {
            let stop = StopAt {
                t_max: (t + PREDICTION_STEP_S).min(t0 + PREDICTION_HORIZON_S),
                hit_plane_x: Some(self.cal.strike.hit_plane_x),
                net: false,
            };
            let ev = self.prop.advance(&mut s, &mut t, &stop);
            points.push(p3(s.pos));
            match ev {
                Event::HitPlane { .. } => {
                    crossing = Some(s.pos);
                    break;
                }
                Event::Floor { .. } | Event::Net { .. } => break,
                Event::Bounce { .. } | Event::TimeLimit { .. } => {}
            }
        }
        let mut path = self.tracked(at, "prediction");
        path.lines.push(fm::LinePrimitive {
            r#type: fm::line_primitive::Type::LineStrip as i32,
            pose: Some(pose(Vec3::zeros(), IDENTITY)),
            thickness: 0.006,
            points,
            color: Some(color(1.0, 0.85, 0.2, 0.9)),
            ..Default::default()
        });
        let mut hit = self.tracked(at, "hit");
        if let Some(p) = crossing {
            hit.spheres.push(fm::SpherePrimitive {
                pose: Some(pose(p, IDENTITY)),
                size: Some(v3(Vec3::repeat(2.0 * BALL_RADIUS))),
                color: Some(color(1.0, 0.85, 0.2, 0.5)),
            });
        }
        vec![path, hit]
    }

    /// The ball ended (a new one started): its prediction errors.
    fn end_ball(&mut self, at: Instant) {
        let plans = std::mem::take(&mut self.ball.plans);
        let Some(last) = plans.last().copied() else { return };
        let truth = self.truth.as_ref().and_then(|t| t.get()).and_then(|hits| {
            hits.iter()
                .filter(|h| h.t.0.abs_diff(last.hit_time.0) < 50_000_000)
                .min_by_key(|h| h.t.0.abs_diff(last.hit_time.0))
        });
        let (ref_t, ref_pos, reference) = match truth {
            Some(h) => (h.t, h.pos, "truth"),
            None => (last.hit_time, last.position, "last plan"),
        };
        for p in &plans {
            let e = PredictionErrorPlot {
                trajectory: p.trajectory,
                seq: p.seq,
                time_to_hit_s: ref_t.secs_since(p.made_at),
                error_mm: (p.position - ref_pos).norm() * 1e3,
                dt_ms: p.hit_time.secs_since(ref_t) * 1e3,
                reference,
            };
            // Log time: when the plan was made (the plot's x is time_to_hit_s).
            self.out.json(Topic::PredictionError, &e, p.made_at.min(at));
        }
    }

    fn plan_view(&mut self, p: &StrikePlan) {
        if self.ball.trajectory != Some(p.trajectory) {
            self.end_ball(p.made_at);
            self.ball.trajectory = Some(p.trajectory);
        }
        self.ball.plans.push(*p);
        let q = quat_zyx(p.orientation.a, p.orientation.b, p.orientation.c);
        let ts = Some(stamp(self.out.wall(p.made_at)));
        self.out.proto(
            Topic::PlanPose,
            &fm::PoseInFrame { timestamp: ts, frame_id: FRAME_TABLE.into(), pose: Some(pose(p.position, q)) },
            p.made_at,
        );
        let mut bat = self.entity(p.made_at, FRAME_TABLE, "bat_plan");
        // The bat face's normal is the tool's x axis (`EulerZyx::face_normal`):
        // a thin cylinder, its axis (z) turned onto x.
        bat.cylinders.push(fm::CylinderPrimitive {
            pose: Some(pose(p.position, face_axis(q))),
            size: Some(v3(Vec3::new(2.0 * BAT_RADIUS, 2.0 * BAT_RADIUS, 0.01))),
            bottom_scale: 1.0,
            top_scale: 1.0,
            color: Some(color(0.85, 0.1, 0.1, 0.8)),
        });
        let speed = p.velocity.norm();
        bat.arrows.push(fm::ArrowPrimitive {
            pose: Some(pose(p.position, quat_x_to(p.velocity))),
            shaft_length: (speed * 0.05).min(0.4),
            shaft_diameter: 0.008,
            head_length: 0.03,
            head_diameter: 0.02,
            color: Some(color(0.85, 0.1, 0.1, 1.0)),
        });
        bat.texts.push(fm::TextPrimitive {
            pose: Some(pose(p.position + Vec3::new(0.0, 0.0, 0.12), IDENTITY)),
            billboard: true,
            font_size: 13.0,
            scale_invariant: true,
            color: Some(color(1.0, 1.0, 1.0, 1.0)),
            text: format!(
                "plan {} · hit in {:.0} ms · conf {:.2}",
                p.seq,
                p.hit_time.secs_since(p.made_at) * 1e3,
                p.confidence
            ),
        });
        self.out.proto(Topic::Robot, &fm::SceneUpdate { deletions: vec![], entities: vec![bat] }, p.made_at);
    }

    fn rsi_view(&mut self, r: &RsiRecord) {
        let Ok(rob) = RobFrame::parse(&r.request[..r.request_len as usize]) else { return };
        let Some(actual) = rob.rist else { return };
        if self.start_pose.is_none() {
            self.start_pose = Some(actual);
        }
        let to_t = |k: &KukaPose| self.cal.robot.b_to_t(Vec3::new(k.x, k.y, k.z) * 1e-3);
        if self.trail.len() == TCP_TRAIL {
            self.trail.pop_front();
        }
        self.trail.push_back((r.arrival, to_t(&actual)));
        self.judge(r.arrival);
        self.rsi_count += 1;
        if !self.rsi_count.is_multiple_of(TCP_DECIMATION)
            || !(self.out.wants(Topic::Tcp) || self.out.wants(Topic::Robot))
        {
            return;
        }
        let commanded = rob.rsol.or_else(|| {
            let sen = SenFrame::parse(&r.answer[..r.answer_len as usize]).ok()?;
            let (k, s) = (sen.rkorr?, self.start_pose?);
            Some(KukaPose::from_array(std::array::from_fn(|i| s.to_array()[i] + k.to_array()[i])))
        });
        let ts = Some(stamp(self.out.wall(r.arrival)));
        let mut poses = vec![kuka_pose(&actual)];
        poses.extend(commanded.as_ref().map(kuka_pose));
        self.out.proto(Topic::Tcp, &fm::PosesInFrame { timestamp: ts, frame_id: FRAME_BASE.into(), poses }, r.arrival);
        let entities = self.robot_entities(r.arrival, &rob, commanded);
        self.out.proto(Topic::Robot, &fm::SceneUpdate { deletions: vec![], entities }, r.arrival);
    }

    /// The robot of one `<Rob>` on `/view/robot`: the arm from the actual
    /// joints (`AIPos`) and its ghost from the commanded ones (`ASPos`), in
    /// T; the actual (`RIst`) and `commanded` TCP as bat discs in B. An element the
    /// controller does not send draws nothing; each expires
    /// [`ROBOT_LIFETIME_S`] after its last update.
    fn robot_entities(&self, at: Instant, rob: &RobFrame, commanded: Option<KukaPose>) -> Vec<fm::SceneEntity> {
        let lifetime = Some(fm::Duration::saturating_from_secs_f64(ROBOT_LIFETIME_S));
        let mut entities = Vec::with_capacity(4);
        for (id, axes, style) in
            [("arm_actual", rob.aipos, &arm::ACTUAL), ("arm_commanded", rob.aspos, &arm::COMMANDED)]
        {
            let Some(deg) = axes else { continue };
            let mut e = fm::SceneEntity { lifetime, ..self.entity(at, FRAME_TABLE, id) };
            e.metadata.push(fm::KeyValuePair { key: "ipoc".into(), value: rob.ipoc.to_string() });
            self.arm.draw(&mut e, &Joints::from_degrees(deg), style);
            if !e.spheres.is_empty() {
                entities.push(e);
            }
        }
        for (id, k, c) in [
            ("tcp_actual", rob.rist, color(0.1, 1.0, 0.3, 1.0)),
            ("tcp_commanded", commanded, color(1.0, 0.2, 0.8, 0.6)),
        ] {
            let Some(k) = k else { continue };
            let mut e = fm::SceneEntity { lifetime, ..self.entity(at, FRAME_BASE, id) };
            let face = kuka_pose(&k);
            e.cylinders.push(fm::CylinderPrimitive {
                pose: Some(fm::Pose { orientation: face.orientation.map(face_axis), ..face }),
                size: Some(v3(Vec3::new(2.0 * BAT_RADIUS, 2.0 * BAT_RADIUS, 0.008))),
                bottom_scale: 1.0,
                top_scale: 1.0,
                color: Some(c),
            });
            entities.push(e);
        }
        entities
    }

    /// The demo's verdicts, once the actual TCP has passed each true hit.
    fn judge(&mut self, now: Instant) {
        let Some(hits) = self.truth.as_ref().and_then(|t| t.get()) else { return };
        while let Some(h) = hits.get(self.judged).copied() {
            if now < h.t + topspin_core::plan::HIT_WINDOW + Duration::from_millis(20) {
                return;
            }
            self.judged += 1;
            let closest = self
                .trail
                .iter()
                .filter(|(t, _)| t.0.abs_diff(h.t.0) <= topspin_core::plan::HIT_WINDOW.0)
                .map(|(t, p)| (p - (h.pos + h.vel * t.secs_since(h.t))).norm())
                .min_by(f64::total_cmp);
            let hit = closest.is_some_and(|d| d <= topspin_core::plan::HIT_RADIUS);
            let (text, c) = match (h.reachable, closest) {
                (false, _) => (format!("ball {}: out of reach", h.ball), color(0.6, 0.6, 0.6, 1.0)),
                (true, Some(d)) if hit => {
                    (format!("ball {}: HIT {:.0} mm", h.ball, d * 1e3), color(0.1, 1.0, 0.2, 1.0))
                }
                (true, Some(d)) => (format!("ball {}: MISS {:.0} mm", h.ball, d * 1e3), color(1.0, 0.15, 0.1, 1.0)),
                (true, None) => (format!("ball {}: MISS (no TCP)", h.ball), color(1.0, 0.15, 0.1, 1.0)),
            };
            let mut e = self.entity(h.t, FRAME_TABLE, &format!("verdict/{}", h.ball));
            e.lifetime = Some(fm::Duration::saturating_from_secs_f64(3.0));
            e.spheres.push(fm::SpherePrimitive {
                pose: Some(pose(h.pos, IDENTITY)),
                size: Some(v3(Vec3::repeat(2.0 * topspin_core::plan::HIT_RADIUS))),
                color: Some(color(c.r, c.g, c.b, 0.3)),
            });
            e.texts.push(fm::TextPrimitive {
                pose: Some(pose(h.pos + Vec3::new(0.0, 0.0, 0.2), IDENTITY)),
                billboard: true,
                font_size: 18.0,
                scale_invariant: true,
                color: Some(c),
                text,
            });
            self.out.proto(Topic::Verdict, &fm::SceneUpdate { deletions: vec![], entities: vec![e] }, h.t);
        }
    }

    fn rsi_event(&mut self, ev: &SessionEvent) {
        match ev {
            SessionEvent::ControllerLate { delay } => self.rsi.controller_late = *delay,
            SessionEvent::SlowAnswer { .. } => self.rsi.slow_answers += 1,
            SessionEvent::PlanAccepted { late_by, .. } if late_by.0 > 0 => self.rsi.plans_late += 1,
            SessionEvent::PlanRejected { .. } => self.rsi.plans_rejected += 1,
            _ => {}
        }
    }
}

impl TelemetrySink for ViewerSink {
    fn datagram(&mut self, d: &DatagramRecord) {
        if let Some(r) = self.out.recording.as_mut() {
            r.datagram(d);
        }
    }

    fn plan(&mut self, p: &StrikePlan) {
        if let Some(r) = self.out.recording.as_mut() {
            r.plan(p);
        }
        self.plan_view(p);
    }

    fn rsi(&mut self, x: &RsiRecord) {
        if let Some(r) = self.out.recording.as_mut() {
            r.rsi(x);
        }
        self.rsi_view(x);
    }

    fn event(&mut self, e: &Telemetry) {
        match e {
            Telemetry::Observed { capture, pos, track } => {
                self.tick(*capture);
                self.observed(*capture, *pos, *track);
            }
            Telemetry::Estimator(EstimatorEvent::Rejected { t, .. }) => self.ball.rejected_t = Some(*t),
            Telemetry::Estimator(EstimatorEvent::Ended { t, .. }) => {
                self.end_ball(Instant::from_secs_f64(*t));
                self.ball.trajectory = None;
            }
            Telemetry::Rsi(ev) => self.rsi_event(ev),
            Telemetry::Answer { arrival, sent } => {
                self.rsi.latency_us = ((*sent - *arrival).0 / 1000).max(1);
                let plot = self.rsi;
                self.out.json(Topic::Rsi, &plot, *arrival);
            }
            _ => {}
        }
    }

    fn logo(&mut self, l: &LogoRecord) {
        let ts = Some(stamp(self.out.wall(l.capture)));
        let side = LOGO_CROP_SIDE as u16;
        let (w, h) = (l.width.min(side), l.height.min(side));
        let n = w as usize * h as usize * 3;
        let image = fm::RawImage {
            timestamp: ts,
            frame_id: "logo_crop".into(),
            width: w as u32,
            height: h as u32,
            encoding: "rgb8".into(),
            step: w as u32 * 3,
            data: foxglove::bytes::Bytes::copy_from_slice(&l.pixels[..n]),
        };
        self.out.proto(Topic::LogoCrop, &image, l.capture);
        self.out.proto(Topic::LogoFit, &logo_annotations(l, ts), l.capture);
        if let (Some(d), Some(p)) = (l.logo_dir, self.ball.last_pos) {
            let mut e = self.tracked(l.capture, "logo");
            e.arrows.push(fm::ArrowPrimitive {
                pose: Some(pose(p, quat_x_to(Vec3::from(d)))),
                shaft_length: 0.04,
                shaft_diameter: 0.004,
                head_length: 0.015,
                head_diameter: 0.01,
                color: Some(color(1.0, 0.1, 0.1, 1.0)),
            });
            self.out.proto(Topic::Ball, &fm::SceneUpdate { deletions: vec![], entities: vec![e] }, l.capture);
        }
    }

    fn queues(&mut self, q: &QueueDepths, at: Instant) {
        self.tick(at);
        self.out.json(Topic::Queues, q, at);
    }

    fn counters(&mut self, json: &serde_json::Value, at: Instant) {
        if let Some(r) = self.out.recording.as_mut() {
            r.counters(json, at);
        }
    }

    fn flush(&mut self) {
        if let Some(r) = self.out.recording.as_mut() {
            r.flush();
        }
    }
}

/// A KUKA pose (mm, degrees A/B/C) as Foxglove's (m, quaternion).
fn kuka_pose(k: &KukaPose) -> fm::Pose {
    pose(Vec3::new(k.x, k.y, k.z) * 1e-3, quat_zyx(k.a.to_radians(), k.b.to_radians(), k.c.to_radians()))
}

/// `/logo/fit` on the crop of `l`: the ball's circle and the detected logo,
/// both in the crop's pixels (the image `/logo/crop` shows).
fn logo_annotations(l: &LogoRecord, ts: Option<fm::Timestamp>) -> fm::ImageAnnotations {
    let mut ann = fm::ImageAnnotations { timestamp: ts, ..Default::default() };
    let [u, v, r] = l.ball_px.map(f64::from);
    ann.circles.push(fm::CircleAnnotation {
        timestamp: ts,
        position: Some(fm::Point2 { x: u, y: v }),
        diameter: 2.0 * r,
        thickness: 1.0,
        fill_color: Some(color(0.0, 0.0, 0.0, 0.0)),
        outline_color: Some(color(0.2, 0.9, 1.0, 1.0)),
        ..Default::default()
    });
    if let Some([lu, lv]) = l.logo_px {
        ann.circles.push(fm::CircleAnnotation {
            timestamp: ts,
            position: Some(fm::Point2 { x: lu.into(), y: lv.into() }),
            diameter: 6.0,
            thickness: 1.0,
            fill_color: Some(color(1.0, 0.1, 0.1, 1.0)),
            outline_color: Some(color(1.0, 1.0, 1.0, 1.0)),
            ..Default::default()
        });
    }
    ann
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::daemon::logo_record;
    use topspin_core::wire::Crop;

    fn sink() -> ViewerSink {
        ViewerSink::new(&Calibration::default_cell(), None, None, None)
    }

    #[test]
    fn log_times_never_run_backwards_on_a_topic() {
        let mut s = sink();
        let o = s.out.offset;
        // A plan made at 10 ms reaches the telemetry thread after an RSI
        // request of 12 ms: both on /view/robot.
        assert_eq!(s.out.log_time(Topic::Robot, Instant(12_000_000)), o + 12_000_000);
        assert_eq!(s.out.log_time(Topic::Robot, Instant(10_000_000)), o + 12_000_000);
        assert_eq!(s.out.log_time(Topic::Robot, Instant(16_000_000)), o + 16_000_000);
        // Another topic keeps its own times.
        assert_eq!(s.out.log_time(Topic::PlanPose, Instant(10_000_000)), o + 10_000_000);
    }

    /// One `<Rob>` draws the actual arm at its `AIPos`, the ghost at its
    /// `ASPos`, and both TCP discs, each with a lifetime; a `<Rob>` without
    /// the joints (an older SEND list, an older recording) only the discs.
    #[test]
    fn the_arm_is_drawn_from_the_joints_the_controller_sends() {
        let s = sink();
        let cal = Calibration::default_cell();
        let (aipos, aspos) = ([10.0, -80.0, 95.0, 5.0, 60.0, -20.0], [12.0, -78.0, 93.0, 5.5, 61.0, -19.0]);
        let k = KukaPose::from_array([350.0, 0.0, 450.0, 180.0, 0.0, 0.0]);
        let rob = RobFrame {
            ipoc: 4208831,
            rist: Some(k),
            rsol: Some(k),
            aipos: Some(aipos),
            aspos: Some(aspos),
            delay: Some(0),
        };
        let entities = s.robot_entities(Instant(4_000_000), &rob, rob.rsol);
        let ids: Vec<_> = entities.iter().map(|e| e.id.as_str()).collect();
        assert_eq!(ids, ["arm_actual", "arm_commanded", "tcp_actual", "tcp_commanded"]);
        let view = ArmView::new(&cal.robot);
        for (e, deg) in entities.iter().zip([aipos, aspos]) {
            assert_eq!(e.frame_id, FRAME_TABLE);
            assert_eq!((e.metadata[0].key.as_str(), e.metadata[0].value.as_str()), ("ipoc", "4208831"));
            let want = view.points(&Joints::from_degrees(deg));
            let got: Vec<_> = e.spheres.iter().map(|s| s.pose.as_ref().unwrap().position.unwrap()).collect();
            assert_eq!(got, want.map(v3));
            // The foot on the calibrated base in T.
            assert_eq!(want[0], Vec3::from(cal.robot.cell.base_in_table_xyz_m));
        }
        assert!(entities[1].spheres.iter().all(|s| s.color.unwrap().a < 1.0), "the ghost is translucent");
        for e in &entities {
            let life = e.lifetime.expect("a lifetime");
            assert!((life.sec() as f64 + life.nsec() as f64 * 1e-9 - ROBOT_LIFETIME_S).abs() < 1e-9, "{}", e.id);
        }

        let old = RobFrame { aipos: None, aspos: None, ..rob };
        let ids: Vec<_> = s.robot_entities(Instant(4_000_000), &old, old.rsol).into_iter().map(|e| e.id).collect();
        assert_eq!(ids, ["tcp_actual", "tcp_commanded"]);
    }

    #[test]
    fn the_balls_entities_expire_after_it() {
        let s = sink();
        let state = BallState { pos: Vec3::new(-1.0, 0.0, 0.3), vel: Vec3::new(5.0, 0.0, 0.5), spin: Vec3::zeros() };
        let mut entities = s.prediction(Instant(1_000_000_000), &state);
        entities.push(s.tracked(Instant(1_000_000_000), "ekf"));
        for e in &entities {
            let life = e.lifetime.expect("a lifetime");
            let secs = life.sec() as f64 + life.nsec() as f64 * 1e-9;
            assert!(secs > 0.0 && (secs - TRACK_LIFETIME_S).abs() < 1e-9, "{}: {secs}", e.id);
        }
    }

    #[test]
    fn the_logo_annotations_are_on_the_crop() {
        // A ball far from the sensor's origin: TTI1 gives its circle in the
        // camera's pixels, the crop is 60 × 60 around it.
        let pixels = vec![0u8; 60 * 60 * 3];
        for (u, v) in [(1500.3f32, 400.7f32), (30.0, 30.0), (1869.9, 1079.2)] {
            let crop = Crop { seq: 1, capture: Instant(5), u, v, radius: 11.5, width: 60, height: 60, pixels: &pixels };
            let seen = topspin_core::logo::SeenLogo { crop_px: [33.0, 27.5], table: Vec3::z() };
            let ann = logo_annotations(&logo_record(&crop, Some(seen)), None);
            assert_eq!(ann.circles.len(), 2);
            for c in &ann.circles {
                let p = c.position.expect("a position");
                assert!((0.0..=60.0).contains(&p.x) && (0.0..=60.0).contains(&p.y), "({}, {}) off the crop", p.x, p.y);
            }
            let ball = ann.circles[0].position.unwrap();
            // The crop starts at (⌊u⌋ − 30, ⌊v⌋ − 30): the ball near its middle.
            assert!((ball.x - 30.0).abs() < 1.0 && (ball.y - 30.0).abs() < 1.0, "ball at ({}, {})", ball.x, ball.y);
            assert!((ann.circles[0].diameter - 23.0).abs() < 1e-6);
        }
    }
}
