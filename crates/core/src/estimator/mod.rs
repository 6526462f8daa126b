//! The streaming estimator the estimator thread owns (DESIGN §4, §6): one
//! observation at a time in, trajectory events and at most one strike plan
//! out. A plain struct with time passed in; no I/O, no allocation after
//! construction (fixed-capacity windows, named capacities), bounded work
//! per observation.
//!
//! Life cycle of a ball: observations after a gap open a *candidate*; once
//! `ACQUIRE_LEN` of them are in, the paper's start filter removes false
//! detections and a cubic fit gives the first state — if the ball moves
//! towards the robot it becomes a *track* (EKF), otherwise it is dropped.
//! A track ends when the ball goes silent, bounces a second time, passes
//! the robot, is returned, stops, or leaves the volume, or when the gate
//! rejects `MAX_CONSECUTIVE_REJECTS` observations in a row (another ball,
//! or a real change of course): those observations then open a new
//! candidate. Past the planned hit, the first observation the gate
//! refuses ends it at once (`EndReason::Struck`): the ball left the bat,
//! and its return's first frames are watched for the spin it brought
//! (`returns`, with `learn.returns`).

pub(crate) mod aim;
pub(crate) mod ekf;
pub(crate) mod returns;
pub(crate) mod session;
mod smooth;
pub(crate) mod spin_prior;
pub(crate) mod stroke;

use heapless::Vec as HVec;

use crate::calib::AimMode;
use crate::calib::Calibration;
use crate::calib::{MAX_HITTING_PLANES, StrikeCalib};
use crate::fit::outlier::{START_WINDOW, StartFilter};
use crate::fit::poly::Cubic;
use crate::fit::refine::SPIN_PRIOR_STD;
use crate::fit::{HitPoint, Prediction, Sample, magnus, predict};
use crate::motion::MotionLimits;
use crate::motion::reach::ReachMap;
use crate::physics::{FlightScales, Propagator, RacketModel, Vec3};
use crate::plan::StrikePlan;
use crate::time::Instant;
pub use aim::{Aim, AimBounds, ArmReach, Landing, aim, bat_velocity, face_normal};
pub use ekf::{Ekf, EkfNoise, Update};
pub use session::{LearnConfig, Learned, LearnedSession};
pub use spin_prior::{BallScale, SPIN_BIN_CENTRES, SPIN_BINS, SpinPrior};
pub use stroke::{Withheld, paper_beta};

/// Observations collected before a candidate becomes a track.
pub(crate) const ACQUIRE_LEN: usize = 8;
/// Capacity of the pre-bounce window the spin is refitted over (≈ 1 s at
/// 250 Hz: longer than any flight to the bounce).
pub(crate) const WINDOW_CAP: usize = 256;
/// Capacity of the post-bounce window the table is read from (≈ 0.5 s at
/// 250 Hz; a longer stretch keeps its first samples).
pub(crate) const AFTER_CAP: usize = 128;
/// Rejections in a row after which a track is given up.
pub(crate) const MAX_CONSECUTIVE_REJECTS: usize = 4;
/// Capacity of the event list of one step.
pub(crate) const EVENTS_CAP: usize = 8;

/// Where the plan's spin comes from.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum SpinSource {
    /// The EKF's spin state (default: measured better, see `topspin eval stream`).
    Ekf,
    /// The paper's fit over the pre-bounce window, imposed on the EKF as a
    /// parameter after every refit.
    WindowFit,
}

/// Settings of the estimator.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct EstimatorConfig {
    /// Silence after which a track ends, s.
    pub silence: f64,
    /// The smallest speed towards the robot that makes a candidate a track, m/s.
    pub min_approach_speed: f64,
    /// Where the plan's spin comes from.
    pub spin_source: SpinSource,
    /// The EKF's noise settings.
    pub noise: EkfNoise,
    /// The paper's start filter applied to a candidate's observations.
    pub start_filter: StartFilter,
    /// Initial spin uncertainty of a new track, rad/s (600: real balls
    /// reach 100–175 rps, and under a saturating lift the first samples
    /// say little about the spin's size, so a narrower start holds the
    /// filter low on fast topspin).
    pub initial_spin_std: f64,
    /// Prior uncertainty of the spin along the flight direction, rad/s
    /// (as [`crate::fit::refine::RefineConfig::prior_along_velocity`]).
    pub spin_prior_along_velocity: f64,
    /// What the estimator learns across the session (drag, table).
    pub learn: LearnConfig,
    /// Re-read the pre-bounce flight in batches, with its drag, as it
    /// grows (`smooth`): the filter alone reads fast spin low.
    pub smooth: bool,
    /// Withhold a plan the arm cannot reach (each hitting plane's reach
    /// map, with the landing aim). Off where the plane is not the arm's
    /// but a question about the ball (`topspin fit stream --hit-plane-x`).
    pub arm_reach: bool,
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        EstimatorConfig {
            silence: 0.1,
            min_approach_speed: 1.0,
            spin_source: SpinSource::Ekf,
            noise: EkfNoise::default(),
            start_filter: StartFilter::default(),
            initial_spin_std: 600.0,
            spin_prior_along_velocity: crate::fit::refine::RefineConfig::default().prior_along_velocity,
            learn: LearnConfig::default(),
            smooth: true,
            arm_reach: true,
        }
    }
}

impl EstimatorConfig {
    /// Tuned for a tracker with per-axis noise `sigma` (m).
    pub fn with_noise(mut self, sigma: f64) -> Self {
        self.noise.measurement = sigma;
        self.start_filter.noise = sigma;
        self
    }
}

/// Why a track ended.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum EndReason {
    /// No observation for longer than [`EstimatorConfig::silence`].
    Silence,
    /// The ball bounced a second time.
    SecondBounce,
    /// The ball is more than 0.3 m beyond the hitting plane.
    PassedRobot,
    /// The ball flies back towards the opponent (v_x < −0.5 m/s).
    Returned,
    /// The ball's speed fell below 0.3 m/s.
    Stopped,
    /// The ball left the tracking volume (z < −0.3 m, |y| > 2.5 m or
    /// x < −3 m in the table frame).
    LeftVolume,
    /// The gate rejected the ball's observations repeatedly.
    Lost,
    /// The planned hit is past and the gate refused an observation: the
    /// ball left the bat (its return is watched: `estimator::returns`).
    Struck,
}

/// Something the telemetry may log.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum EstimatorEvent {
    /// A candidate became a track.
    Started {
        /// Id of the new track.
        trajectory: u32,
        /// Time of the candidate's last observation, s.
        t: f64,
        /// Candidate observations the start filter removed.
        start_outliers: u8,
    },
    /// A track ended.
    Ended {
        /// Id of the track.
        trajectory: u32,
        /// Time the track ended, s.
        t: f64,
        /// Why it ended.
        reason: EndReason,
    },
    /// A candidate that did not move towards the robot.
    Discarded {
        /// Time of the candidate's last inlier, s.
        t: f64,
    },
    /// The gate rejected an observation of the track.
    Rejected {
        /// Id of the track.
        trajectory: u32,
        /// Time of the rejected observation, s.
        t: f64,
        /// Squared Mahalanobis distance of the observation.
        d2: f64,
    },
    /// The track's ball bounced (confirmed by an accepted observation after
    /// it).
    Bounce {
        /// Id of the track.
        trajectory: u32,
        /// Time of the bounce, s.
        t: f64,
    },
    /// A prediction produced no plan.
    Withheld {
        /// Id of the track.
        trajectory: u32,
        /// Time of the prediction, s.
        t: f64,
        /// Why no plan was published.
        reason: Withheld,
    },
    /// A spin from the logo thread, fused into the track (`accepted`) or
    /// refused by the gate; `d2` its squared Mahalanobis distance.
    LogoSpin {
        /// Id of the track.
        trajectory: u32,
        /// Time of the track's last observation, s.
        t: f64,
        /// True when the spin was fused, false when the gate refused it.
        accepted: bool,
        /// Squared Mahalanobis distance of the logo spin.
        d2: f64,
    },
    /// The session learned from an ended track's bounce (learning on):
    /// what it holds now, for the next balls.
    Learned {
        /// Id of the track it learned from.
        trajectory: u32,
        /// Multiplier of the calibrated drag.
        drag: f32,
        /// Table restitution e.
        restitution: f32,
        /// Ball–table friction μ.
        friction: f32,
        /// σ of the velocity just after a bounce that the table leaves
        /// unexplained, per axis (x, y, z), m/s.
        bounce_sigma: [f32; 3],
        /// The spin the table meets per unit of the spin a flight shows,
        /// per bin of the flight's spin parameter
        /// ([`spin_prior::SPIN_BIN_CENTRES`]): the next balls' spin prior.
        spin_scale: [f32; spin_prior::SPIN_BINS],
        /// Balls whose own spin the session keeps with their speed and
        /// lift direction ([`SpinPrior::ball_scale`]).
        spin_by_speed: u8,
    },
    /// A bounce no table explains (a net-cord ball, the table's edge, a
    /// tracker jump at the bounce): the session learned nothing from it.
    BounceUnexplained {
        /// Id of the track.
        trajectory: u32,
        /// Time of the bounce, s.
        t: f64,
    },
}

/// A spin measured from the ball's logo (the logo thread's result).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LogoSpin {
    /// Capture time of the last crop it was fitted over.
    pub last_crop: Instant,
    /// rad/s, table frame.
    pub spin: Vec3,
    /// Its covariance, (rad/s)².
    pub cov: nalgebra::Matrix3<f64>,
}

/// What one observation produced.
#[derive(Clone, Debug, Default)]
pub struct StepOutput {
    /// Events of this step, in order.
    pub events: HVec<EstimatorEvent, EVENTS_CAP>,
    /// A new plan to publish.
    pub plan: Option<StrikePlan>,
}

impl StepOutput {
    fn push(&mut self, e: EstimatorEvent) {
        // A full list drops the rest; EVENTS_CAP exceeds the most one step emits.
        let _ = self.events.push(e);
    }
}

#[derive(Clone, Debug)]
struct Track {
    id: u32,
    ekf: Ekf,
    /// The physics this ball flies with: the calibration with the
    /// session's drag and table.
    prop: Propagator,
    last_t: f64,
    rejects: HVec<Sample, MAX_CONSECUTIVE_REJECTS>,
    window: HVec<Sample, WINDOW_CAP>,
    /// The spin the ball flew with before its bounce (the Magnus spin the
    /// stroke answers, as in the paper); `None` before the bounce.
    spin_before_bounce: Option<Vec3>,
    /// Time of the bounce, once confirmed.
    bounce_t: Option<f64>,
    /// Accepted observations after the bounce, short of the hitting plane.
    after: HVec<Sample, AFTER_CAP>,
    /// The filter just before the bounce it has passed: where a bounce
    /// that surprised it is flown again ([`rescue_bounce`]).
    pre_bounce: Option<Ekf>,
    /// The aim of the return (`strike.aim = "landing"`): the next
    /// refinement resumes its searches.
    aim: aim::Searches,
    /// The batch reading the window now, if any, and the window's length
    /// when the last one began.
    batch: Option<smooth::Batch>,
    batch_from: usize,
    /// A batch has read this flight: its drag replaces the cubic's.
    smoothed: bool,
    /// The plane of the hitting volume the last plan met the ball on.
    hit_x: Option<f64>,
    /// Where this ball's return is aimed (`strike.aim_strategy`), m.
    target: [f64; 2],
    /// The spin the ceiling camera read (rad/s, table frame) and the σ of
    /// the ln of its scale against the flight's reading, once fused.
    logo: Option<(Vec3, f64)>,
    /// Speed at the net as the filter last showed it before the bounce,
    /// m/s ([`speed_at_net`]): what the session's spin prior weighs alike
    /// balls by, the same point of every flight wherever the tracker
    /// first saw it.
    speed0: f64,
    /// σ of ln(spin) the aim allows above the estimate: the camera's, or
    /// the session's for this ball ([`BallScale::hedge`]).
    spin_hedge: f64,
    /// The latest plan's stroke after the bounce, whose return will read
    /// the ball's spin (learning the spin on, the camera not read).
    stroke: Option<returns::Stroke>,
}

/// A logo spin more than this far from the flight's own spin direction is
/// not taken as a measure of the flight's scale, rad (45°).
const LOGO_MAX_ANGLE_RAD: f64 = std::f64::consts::FRAC_PI_4;
/// Least σ of the ln of a logo spin's scale: the rotation fit's
/// covariance leaves out what the logo's detection gets wrong.
pub const LOGO_SCALE_SIGMA_FLOOR: f64 = 0.05;

/// The spin the camera read (`logo`) per unit of the flight's reading
/// (`flight`): the least-squares scale along the flight's spin, within
/// the spin prior's grid (×0.5–4); `None` where the flight shows no spin
/// or the two point more than [`LOGO_MAX_ANGLE_RAD`] apart.
fn logo_scale(logo: &Vec3, flight: &Vec3) -> Option<f64> {
    let (l, f) = (logo.norm(), flight.norm());
    let dot = logo.dot(flight);
    if !(f > 1.0 && l > 1.0 && dot >= l * f * LOGO_MAX_ANGLE_RAD.cos()) {
        return None;
    }
    Some((dot / (f * f)).clamp(0.5, 4.0))
}

/// The estimator: at most one ball tracked at a time (the one coming at
/// the robot).
///
/// Observations go in with their capture time; events and, once the ball
/// is understood, a strike plan come out. Here a ball is flown with the
/// calibration's own physics and observed at 200 Hz:
///
/// ```
/// use topspin_core::calib::Calibration;
/// use topspin_core::estimator::{Estimator, EstimatorConfig};
/// use topspin_core::physics::{BallState, Event, StopAt, Vec3};
/// use topspin_core::time::Instant;
///
/// let cal = Calibration::default_cell();
/// let prop = cal.propagator();
/// let mut estimator = Estimator::new(&cal, EstimatorConfig::default());
///
/// // A topspin ball from the opponent's end towards the robot, seen until
/// // it has bounced on the robot's half.
/// let mut ball = BallState::new(Vec3::new(-1.6, 0.0, 0.35), Vec3::new(5.5, 0.0, 1.2), Vec3::new(0.0, 150.0, 0.0));
/// let (mut t, mut last_plan) = (0.0, None);
/// while ball.pos.x < 1.0 {
///     let out = estimator.observe(Instant((t * 1e9) as u64), ball.pos);
///     last_plan = out.plan.or(last_plan);
///     let next = t + 0.005;
///     while matches!(prop.advance(&mut ball, &mut t, &StopAt::time(next)), Event::Bounce { .. }) {}
/// }
/// let plan = last_plan.expect("a stroke is planned before the ball arrives");
/// assert!(plan.hit_time > Instant((t * 1e9) as u64), "planned ahead");
/// assert!(plan.spin.y > 0.0, "topspin read as topspin");
/// ```
#[derive(Debug)]
pub struct Estimator {
    cfg: EstimatorConfig,
    prop: Propagator,
    strike: crate::calib::StrikeCalib,
    racket: RacketModel,
    aim_bounds: aim::AimBounds,
    /// The hitting volume's planes, ascending (`strike.hit_depth_x`).
    planes: heapless::Vec<f64, MAX_HITTING_PLANES>,
    /// What the arm can do over the hitting window on each of them
    /// (`strike.aim = "landing"`; empty otherwise): the aim keeps to the
    /// faces it can present and the bat speeds it delivers.
    reach: Vec<ReachMap>,
    candidate: HVec<Sample, START_WINDOW>,
    track: Option<Track>,
    next_id: u32,
    plan_seq: u32,
    last_prediction: Option<Prediction>,
    session: LearnedSession,
    /// The last stroke's return, while it is watched.
    watch: Option<returns::Watch>,
    /// σ of ln(drag multiplier) of one flight about the session's
    /// (`physics.flight_variation.drag`): the batch's prior.
    drag_variation: f64,
}

/// The arm's reach over the calibration's hitting window on the plane x,
/// for the faces the aim sets there (its tilt range, heading at the
/// target, the roll).
fn reach_map(cal: &Calibration, x: f64) -> ReachMap {
    let s = &cal.strike;
    ReachMap::new(
        &MotionLimits::from_robot(&cal.robot),
        x,
        s.window_y,
        s.window_z,
        s.aim_tilt_deg.map(f64::to_radians),
        s.aim_target,
        |y| stroke::bat_roll(s, y),
    )
}

impl Estimator {
    /// An idle estimator for the cell `cal` (physics, table, strike) with
    /// settings `cfg`.
    pub fn new(cal: &Calibration, cfg: EstimatorConfig) -> Self {
        let planes = cal.strike.hitting_planes();
        let reach = match cal.strike.aim {
            // One thread per plane: start-up, not the hot path (each map
            // is a few thousand inverse kinematics).
            AimMode::Landing if cfg.arm_reach => std::thread::scope(|scope| {
                let maps: Vec<_> = planes.iter().map(|&x| scope.spawn(move || reach_map(cal, x))).collect();
                maps.into_iter().map(|m| m.join().expect("a reach map's thread panicked")).collect()
            }),
            AimMode::Landing | AimMode::Paper => Vec::new(),
        };
        Estimator {
            cfg,
            prop: cal.propagator(),
            strike: cal.strike.clone(),
            racket: cal.racket_model(),
            aim_bounds: aim::AimBounds::of(&cal.strike),
            planes,
            reach,
            candidate: HVec::new(),
            track: None,
            next_id: 1,
            plan_seq: 0,
            last_prediction: None,
            session: LearnedSession::new(&cal.physics.bounce_model(), &cfg.noise.bounce_vel),
            watch: None,
            drag_variation: cal.physics.variation.drag,
        }
    }

    /// What the session has learned so far.
    pub fn session(&self) -> &LearnedSession {
        &self.session
    }

    /// The physics a new ball flies with: the calibration, with the
    /// session's drag and table where learning is on.
    fn session_propagator(&self) -> Propagator {
        if !self.cfg.learn.enabled {
            return self.prop;
        }
        let scales = FlightScales { drag: self.session.drag.value, lift: 1.0 };
        Propagator { bounce: self.session.bounce_model(&self.prop.bounce), ..self.prop.with_scales(scales) }
    }

    /// Ends the track (if any) and learns the table from its bounce, and
    /// how much of the velocity after it the table left unexplained
    /// ([`EstimatorEvent::Learned`] where it did).
    fn end_track(&mut self, out: &mut StepOutput) {
        let Some(track) = self.track.take() else { return };
        if !self.cfg.learn.enabled || track.ekf.bounces != 1 {
            return;
        }
        let (Some(before), Some(t_bounce)) = (track.ekf.last_contact, track.bounce_t) else { return };
        let (cfg, sigma) = (self.cfg.learn, self.cfg.noise.measurement);
        if let Some((after, after_var)) = session::velocity_at(&track.after, t_bounce, cfg.min_samples, sigma) {
            // Against the table this ball flew with, before it learns from it.
            let table = track.prop.bounce;
            let residual = after - table.apply(&before).vel;
            let explained = track.ekf.contact_vel_var + Vec3::repeat(after_var);
            // Against the session's own table: what it needs to explain the kick.
            let var = self.session.bounce_noise() + explained;
            let plain = self.session.bounce_model(&self.prop.bounce);
            let s_shown = spin_prior::spin_parameter(&before, table.radius);
            let scale = self.session.spin.scale_at(s_shown);
            let as_flown = session::bounce_explained(&before, &after, &var, &table)
                || session::bounce_explained(&before, &after, &var, &plain.with_spin_scale(scale));
            // A bounce that surprised the filter (its spin far from the
            // flight's reading) is explained, if at all, by a spin the bins
            // did not expect: it teaches the spin prior, not the table or
            // its noise, which assume the spin the bins give.
            let spin_free = !as_flown && {
                let best = spin_prior::best_scale(&before, &after, &var, &plain);
                session::bounce_explained(&before, &after, &var, &plain.with_spin_scale(best))
            };
            if !(as_flown || spin_free) {
                self.session.unexplained = self.session.unexplained.saturating_add(1);
                out.push(EstimatorEvent::BounceUnexplained { trajectory: track.id, t: t_bounce });
                return;
            }
            if as_flown {
                self.session.take_bounce_residual(&residual, &explained, &cfg);
            }
            if cfg.spin {
                let read = track.ekf.contact_vel_var_read + Vec3::repeat(after_var);
                self.session.spin.take(&before, &after, &read, &plain, track.speed0, track.id);
            }
            if as_flown {
                // The table, from the spin it met.
                let met =
                    crate::physics::BallState { spin: before.spin * self.session.spin.scale_at(s_shown), ..before };
                self.session.take_bounce(&met, &after, self.prop.bounce.radius, &cfg);
            }
            out.push(self.learned(track.id));
        }
    }

    /// What the session holds now, learned from `trajectory`.
    fn learned(&self, trajectory: u32) -> EstimatorEvent {
        let s = &self.session;
        EstimatorEvent::Learned {
            trajectory,
            drag: s.drag.value as f32,
            restitution: s.restitution.value as f32,
            friction: s.friction.value as f32,
            bounce_sigma: s.bounce_noise().map(|v| v.sqrt() as f32).into(),
            spin_scale: s.spin.scales().map(|v| v as f32),
            spin_by_speed: s.spin.kept_by_speed() as u8,
        }
    }

    /// Takes one observation into the watched return (if any); true where
    /// it was the return's. The watch ends (its spin read and learned)
    /// once full or past its span.
    fn watch_return(&mut self, sample: Sample, out: &mut StepOutput) -> bool {
        let Some(watch) = &mut self.watch else { return false };
        if watch.over(sample.t) {
            self.end_watch(out);
            return false;
        }
        if watch.push(sample) {
            self.end_watch(out);
        }
        true
    }

    /// Reads the watched return's spin and learns it.
    fn end_watch(&mut self, out: &mut StepOutput) {
        let Some(watch) = self.watch.take() else { return };
        let flight = self.session_propagator().flight;
        let Some(read) = watch.read(&self.racket, &flight, self.cfg.noise.measurement) else { return };
        let st = &watch.stroke;
        if self.session.spin.take_read(
            &st.before_bounce,
            read.scale,
            read.sigma,
            &self.prop.bounce,
            st.speed0,
            st.trajectory,
        ) {
            self.session.returns_read = self.session.returns_read.saturating_add(1);
            out.push(self.learned(st.trajectory));
        }
    }

    /// The current track's id and EKF, if tracking.
    pub fn tracking(&self) -> Option<(u32, &Ekf)> {
        self.track.as_ref().map(|t| (t.id, &t.ekf))
    }

    /// The prediction behind the latest plan or withheld plan.
    pub fn last_prediction(&self) -> Option<&Prediction> {
        self.last_prediction.as_ref()
    }

    /// Ends a silent track; call when no observation has come for a while.
    pub fn poll(&mut self, now: Instant, out: &mut StepOutput) {
        let t = now.as_secs_f64();
        if self.watch.as_ref().is_some_and(|w| w.over(t)) {
            self.end_watch(out);
        }
        if let Some(track) = &self.track
            && t - track.last_t > self.cfg.silence
        {
            out.push(EstimatorEvent::Ended { trajectory: track.id, t, reason: EndReason::Silence });
            self.end_track(out);
        }
        if let Some(last) = self.candidate.last()
            && t - last.t > self.cfg.silence
        {
            self.candidate.clear();
        }
    }

    /// Fuses a logo spin into the current track, if it is of this ball:
    /// the crops were taken while the track was alive and before its
    /// bounce (the bounce changes the spin). The filter's spin is a
    /// constant of the flight model, so the measurement applies now.
    pub fn observe_logo_spin(&mut self, m: &LogoSpin) -> Option<EstimatorEvent> {
        let track = self.track.as_mut()?;
        let t = m.last_crop.as_secs_f64();
        let started = track.window.first().map(|s| s.t).unwrap_or(track.last_t);
        if track.spin_before_bounce.is_some() || t < started - self.cfg.silence || t > track.last_t + self.cfg.silence {
            return None;
        }
        // The filter's spin is the flight's reading of it, through the
        // calibration's lift: the camera's spin is brought to that reading
        // by the scale between them, which carries its size; the filter
        // takes its direction (its gate checks that), the table and the
        // stroke its size.
        let flight = track.ekf.state();
        let scale = logo_scale(&m.spin, &flight.spin);
        let (z, r) = match scale {
            Some(k) => (m.spin / k, m.cov / (k * k)),
            None => (m.spin, m.cov),
        };
        let (accepted, d2) = match track.ekf.update_spin(&z, &r) {
            Update::Accepted { d2 } => (true, d2),
            Update::Rejected { d2 } => (false, d2),
        };
        let event = EstimatorEvent::LogoSpin { trajectory: track.id, t: track.last_t, accepted, d2 };
        if accepted && let Some(k) = scale {
            let along = flight.spin.normalize();
            let sigma =
                ((along.transpose() * m.cov * along)[0].max(0.0).sqrt() / m.spin.norm()).max(LOGO_SCALE_SIGMA_FLOOR);
            track.logo = Some((m.spin, sigma));
            if self.cfg.learn.enabled && self.cfg.learn.spin {
                self.session.spin.take_read(&flight, k, sigma, &self.prop.bounce, track.speed0, track.id);
            }
        }
        self.refresh_spin_scale();
        Some(event)
    }

    /// Takes one observation (capture time on our clock, position in the
    /// table frame; the caller has validated it).
    pub fn observe(&mut self, capture: Instant, pos: Vec3) -> StepOutput {
        let mut out = StepOutput::default();
        let t = capture.as_secs_f64();
        self.poll(capture, &mut out);
        let sample = Sample::new(t, pos);
        if self.track.is_some() {
            self.track_step(sample, &mut out);
        } else if !self.watch_return(sample, &mut out) {
            self.acquire(sample, &mut out);
        }
        out
    }

    fn acquire(&mut self, sample: Sample, out: &mut StepOutput) {
        if let Some(last) = self.candidate.last()
            && sample.t <= last.t
        {
            return; // out of order or duplicate
        }
        let _ = self.candidate.push(sample);
        if self.candidate.len() < ACQUIRE_LEN {
            return;
        }
        let outliers = self.cfg.start_filter.outliers(&self.candidate);
        let mut inliers: HVec<Sample, START_WINDOW> = HVec::new();
        for (i, s) in self.candidate.iter().enumerate() {
            if !outliers.contains(&i) {
                let _ = inliers.push(*s);
            }
        }
        self.candidate.clear();
        let Some(cubic) = Cubic::fit(inliers.iter()) else { return };
        let last = inliers[inliers.len() - 1];
        let vel = cubic.vel(last.t);
        if vel.x < self.cfg.min_approach_speed {
            out.push(EstimatorEvent::Discarded { t: last.t });
            return;
        }
        // The linear solve assumes k_M(0); a saturating lift needs more spin
        // for the same bend (as the batch fit and `refit_spin` map it).
        let flight = &self.prop.flight;
        let spin = magnus::solve(&cubic, inliers.iter().map(|s| s.t), flight)
            .map(|m| flight.spin_from_linear(&m.spin_linear, m.mean_speed).unwrap_or(m.spin_linear))
            .filter(|w| w.norm() < 1500.0)
            .unwrap_or_else(Vec3::zeros);
        // A trajectory cannot see the spin along the flight direction: start
        // it at zero with the refined fit's prior (spin is imparted
        // perpendicular to the exit velocity), the rest from the cubic.
        let first = cubic.vel(inliers[0].t).normalize();
        let spin = spin - first * first.dot(&spin);
        // Start the filter at the first inlier and run it over all of them,
        // so the early samples (the spin's lever arm) count fully.
        let t_first = inliers[0].t;
        let state = crate::physics::BallState::new(cubic.pos(t_first), cubic.vel(t_first), spin);
        let sigma = self.cfg.noise.measurement;
        let mut noise = self.cfg.noise;
        if self.cfg.learn.enabled {
            noise.bounce_vel = self.session.bounce_noise();
        }
        let mut ekf = Ekf::new(t_first, &state, 2.0 * sigma, 0.6, self.cfg.initial_spin_std, noise);
        let along = first * first.transpose();
        let spin_cov = (nalgebra::Matrix3::identity() - along) * self.cfg.initial_spin_std.powi(2)
            + along * self.cfg.spin_prior_along_velocity.powi(2);
        ekf.p.fixed_view_mut::<3, 3>(6, 6).copy_from(&spin_cov);
        let mut prop = self.session_propagator();
        let speed0 = speed_at_net(&state, &self.prop.flight);
        let mut spin_hedge = ekf.noise.bounce_spin_share;
        if self.cfg.learn.enabled && self.cfg.learn.spin {
            let b = self.session.spin.ball_scale(&ekf.state(), prop.bounce.radius, speed0);
            prop.bounce = prop.bounce.with_spin_scale(b.scale);
            ekf.noise.bounce_spin_share = b.share;
            spin_hedge = b.hedge;
        }
        for s in &inliers {
            ekf.predict(&prop, s.t);
            ekf.update(&s.pos);
        }
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1);
        let mut window = HVec::new();
        for s in &inliers {
            let _ = window.push(*s);
        }
        self.track = Some(Track {
            id,
            ekf,
            prop,
            last_t: last.t,
            rejects: HVec::new(),
            window,
            spin_before_bounce: None,
            bounce_t: None,
            after: HVec::new(),
            pre_bounce: None,
            aim: aim::Searches::default(),
            batch: None,
            batch_from: 0,
            smoothed: false,
            hit_x: None,
            target: self.strike.aim_target_for(id, inliers[0].pos.y),
            logo: None,
            speed0,
            spin_hedge,
            stroke: None,
        });
        out.push(EstimatorEvent::Started { trajectory: id, t: last.t, start_outliers: outliers.len() as u8 });
        self.refresh_spin_scale();
        self.plan(last.t, out);
    }

    fn track_step(&mut self, sample: Sample, out: &mut StepOutput) {
        let cfg = self.cfg;
        let track = self.track.as_mut().expect("tracking");
        if sample.t <= track.ekf.t {
            return; // out of order or duplicate
        }
        let mut trial = track.ekf;
        if let Some(tb) = trial.predict(&track.prop, sample.t) {
            // Only a tentative bounce until the observation is accepted.
            let mut accepted = matches!(trial.update(&sample.pos), Update::Accepted { .. });
            if !accepted && track.spin_before_bounce.is_none() {
                // The first sample after the bounce surprised the filter:
                // the spin the table met may be far from the flight's.
                if let Some(wide) = flown_wide(track.ekf, &track.prop, std::iter::once(&sample)) {
                    track.ekf.noise.bounce_spin_share = wide.noise.bounce_spin_share;
                    self.session.surprised = self.session.surprised.saturating_add(1);
                    accepted = true;
                }
            }
            if accepted {
                out.push(EstimatorEvent::Bounce { trajectory: track.id, t: tb });
                if track.spin_before_bounce.is_none() {
                    track.pre_bounce = Some(track.ekf);
                    track.bounce_t = Some(tb);
                    if cfg.learn.enabled
                        && let Some(drag) = own_drag(track, &self.prop, cfg.learn.min_samples)
                    {
                        // The air of this session, this ball's flight included,
                        // for the next balls; this ball flies on with its own
                        // drag weighed against it.
                        self.session.take_drag(drag, &cfg.learn);
                        let scales =
                            FlightScales { drag: cfg.learn.ball_drag(&self.session.drag, Some(drag)), lift: 1.0 };
                        track.prop.flight = self.prop.flight.scaled(scales);
                    }
                    // A batch of the window still running ends with it (its
                    // result is for the flight before the bounce).
                    track.batch = None;
                    track.spin_before_bounce = Some(track.ekf.state().spin);
                }
            }
            trial = track.ekf;
            trial.predict(&track.prop, sample.t);
        }
        match trial.update(&sample.pos) {
            Update::Accepted { .. } => {
                if trial.own_half_bounces > track.ekf.own_half_bounces {
                    // A serve's bounce on its own half: the flight the spin
                    // is read from starts again after it.
                    track.window.clear();
                    track.batch = None;
                    track.batch_from = 0;
                    track.smoothed = false;
                }
                track.ekf = trial;
                track.last_t = sample.t;
                track.rejects.clear();
                if track.spin_before_bounce.is_none() {
                    let _ = track.window.push(sample);
                    let n = track.window.len();
                    let ball_drag_now = cfg.learn.enabled
                        && cfg.learn.ball_drag_weight > 0.0
                        && n >= cfg.learn.min_samples
                        && n.is_multiple_of(cfg.learn.ball_drag_every.max(1))
                        && !track.window.is_full()
                        && !track.smoothed;
                    if ball_drag_now {
                        track.prop.flight = ball_flight(&self.prop, &self.session, &cfg, &track.window);
                    }
                    if cfg.smooth {
                        if track.batch.is_none()
                            && smooth::due(&track.window, track.batch_from)
                            && !track.window.is_full()
                        {
                            start_batch(track, &self.prop, &self.session, &cfg, self.drag_variation);
                        }
                        advance_batch(track, smooth::SAMPLES_PER_STEP);
                    }
                    if cfg.spin_source == SpinSource::WindowFit {
                        let prop = track.prop;
                        refit_spin(track, &prop);
                    }
                } else if track.ekf.bounces == 1 && sample.pos.x < self.strike.hit_plane_x {
                    let _ = track.after.push(sample);
                }
            }
            Update::Rejected { .. } if rescue_bounce(track, &sample, self.strike.hit_plane_x).is_some() => {
                self.session.surprised = self.session.surprised.saturating_add(1);
            }
            Update::Rejected { d2 } => {
                out.push(EstimatorEvent::Rejected { trajectory: track.id, t: sample.t, d2 });
                if let Some(stroke) = track.stroke.filter(|s| sample.t > s.t_hit) {
                    // The stroke is past and the ball left its path: the
                    // track ends, and its return is watched.
                    let id = track.id;
                    out.push(EstimatorEvent::Ended { trajectory: id, t: sample.t, reason: EndReason::Struck });
                    self.end_track(out);
                    self.watch = Some(returns::Watch::new(stroke));
                    self.watch_return(sample, out);
                    return;
                }
                if track.rejects.push(sample).is_err() || track.rejects.is_full() {
                    let id = track.id;
                    let rejected = track.rejects.clone();
                    out.push(EstimatorEvent::Ended { trajectory: id, t: sample.t, reason: EndReason::Lost });
                    self.end_track(out);
                    self.candidate.clear();
                    for s in &rejected {
                        let _ = self.candidate.push(*s);
                    }
                }
                return;
            }
        }
        if let Some(reason) = self.ended(sample.t) {
            let id = self.track.as_ref().map_or(0, |t| t.id);
            out.push(EstimatorEvent::Ended { trajectory: id, t: sample.t, reason });
            self.end_track(out);
            return;
        }
        self.refresh_spin_scale();
        self.plan(sample.t, out);
    }

    /// Sets the spin the table will meet for the flight shown so far (as
    /// the camera read it, else as the session learned it), against the
    /// filter's spin as it is now: after each observation and batch, and
    /// after the camera's spin, so that the plan and the next bounce take
    /// the scale of the spin they multiply (a batch can move the flight's
    /// spin by half between two observations). Frozen at the bounce.
    fn refresh_spin_scale(&mut self) {
        let Some(track) = &mut self.track else { return };
        if track.spin_before_bounce.is_some() {
            return;
        }
        let state = track.ekf.state();
        track.speed0 = speed_at_net(&state, &self.prop.flight);
        if let Some((logo, sigma)) = track.logo
            && let Some(k) = logo_scale(&logo, &state.spin)
        {
            track.prop.bounce = track.prop.bounce.with_spin_scale(k);
            track.ekf.noise.bounce_spin_share = sigma;
            track.spin_hedge = sigma;
        } else if self.cfg.learn.enabled && self.cfg.learn.spin {
            let b = self.session.spin.ball_scale(&state, self.prop.bounce.radius, track.speed0);
            track.prop.bounce = track.prop.bounce.with_spin_scale(b.scale);
            track.ekf.noise.bounce_spin_share = b.share;
            track.spin_hedge = b.hedge;
        }
    }

    fn ended(&self, _t: f64) -> Option<EndReason> {
        let track = self.track.as_ref()?;
        let s = track.ekf.state();
        if track.ekf.bounces >= 2 {
            Some(EndReason::SecondBounce)
        } else if s.pos.x > self.strike.depth()[1] + 0.3 {
            Some(EndReason::PassedRobot)
        } else if s.vel.x < -0.5 {
            Some(EndReason::Returned)
        } else if s.vel.norm() < 0.3 {
            Some(EndReason::Stopped)
        } else if s.pos.z < -0.3 || s.pos.y.abs() > 2.5 || s.pos.x < -3.0 {
            Some(EndReason::LeftVolume)
        } else {
            None
        }
    }

    fn plan(&mut self, t: f64, out: &mut StepOutput) {
        let Some(track) = &mut self.track else { return };
        let state = track.ekf.state();
        // Bounced already: the ball is played before its next bounce.
        let bounced = track.ekf.bounces > 0;
        let prediction = predict(&track.prop, &state, t, self.strike.hit_plane_x, bounced);
        self.last_prediction = Some(prediction);
        let volume = HittingVolume { strike: &self.strike, planes: &self.planes, reach: &self.reach };
        let (hit, plane) = match volume.choose(&track.prop, &state, t, &prediction, track.hit_x, bounced) {
            Ok(chosen) => chosen,
            Err(reason) => {
                out.push(EstimatorEvent::Withheld { trajectory: track.id, t, reason });
                return;
            }
        };
        track.hit_x = Some(self.planes[plane]);
        // The spin the ball flew with (before its bounce) decides the
        // stroke: the spin the table meets, not the flight's reading of it.
        let scale = track.prop.bounce.spin_scale;
        let spin = track.spin_before_bounce.unwrap_or(state.spin) * scale;
        let hit_state = crate::physics::BallState { spin: hit.state.spin * scale, ..hit.state };
        self.plan_seq = self.plan_seq.wrapping_add(1);
        let tau = hit.t - t;
        let p = &track.ekf.p;
        let k_m = self.prop.flight.k_m0() * state.vel.norm();
        let var = p.fixed_view::<3, 3>(0, 0).trace()
            + tau * tau * p.fixed_view::<3, 3>(3, 3).trace()
            + (0.5 * tau * tau * k_m).powi(2) * p.fixed_view::<3, 3>(6, 6).trace();
        let confidence = 1.0 / (1.0 + var / (0.02 * 0.02));
        let (orientation, velocity) = match self.strike.aim {
            AimMode::Paper => {
                (stroke::bat_orientation(&self.strike, &spin, hit.state.pos.y), stroke::bat_velocity(&self.strike))
            }
            AimMode::Landing => {
                let tilt0 = -stroke::paper_beta(&self.strike, &spin);
                let target = track.target;
                let p = &hit.state.pos;
                let bounds = match self.reach.get(plane) {
                    Some(m) => self.aim_bounds.within(aim::ArmReach::at(m, p.y, p.z)),
                    None => self.aim_bounds,
                };
                // The return flies with the spin the rubber gave it.
                let prop = Propagator { bounce: track.prop.bounce.with_spin_scale(1.0), ..track.prop };
                let a = track.aim.step(
                    &bounds,
                    target,
                    &prop,
                    &self.racket,
                    &hit_state,
                    track.spin_hedge,
                    tilt0,
                    aim::AIM_BUDGET,
                );
                let roll = match bounds.arm {
                    Some(arm) => arm.roll(a.tilt),
                    None => stroke::bat_roll(&self.strike, hit.state.pos.y),
                };
                (
                    crate::geometry::EulerZyx { a: a.heading, b: a.tilt, c: roll },
                    aim::bat_velocity(a.tilt, a.heading, a.speed),
                )
            }
        };
        if self.cfg.learn.enabled && self.cfg.learn.spin && self.cfg.learn.returns && track.logo.is_none() {
            track.stroke = track.ekf.last_contact.map(|before_bounce| returns::Stroke {
                trajectory: track.id,
                t_hit: hit.t,
                pos: hit.state.pos,
                vel: hit.state.vel,
                before_bounce,
                table: track.prop.bounce,
                normal: orientation.face_normal(),
                bat_vel: velocity,
                speed0: track.speed0,
            });
        }
        out.plan = Some(StrikePlan {
            seq: self.plan_seq,
            trajectory: track.id,
            made_at: Instant::from_secs_f64(t),
            hit_time: Instant::from_secs_f64(hit.t),
            position: hit.state.pos,
            velocity,
            orientation,
            spin,
            confidence,
        });
    }
}

/// Where along its predicted path the ball is met: the hitting plane, or
/// the nearest other plane of the volume whose crossing lies in the window
/// with the arm able to present a face there.
struct HittingVolume<'a> {
    strike: &'a StrikeCalib,
    planes: &'a [f64],
    /// Per plane, where the aim uses the arm's reach (else empty).
    reach: &'a [ReachMap],
}

/// How far inside the window a hitting point on the nominal plane must lie
/// for the volume's other planes not to be weighed, m: a ball that passes
/// it at the edge is met where it passes with room to spare.
const WINDOW_MARGIN_M: f64 = 0.03;

/// The least time before the hit at which a ball's stroke may move to
/// another plane, s: later, the stroke under way is kept (a late hop asked
/// the axes for more than their rates allow).
const PLANE_HOP_LEAD_S: f64 = 0.15;

impl HittingVolume<'_> {
    /// The hitting point and its plane's index:
    /// - the plane the last plan of this ball chose, while it works there
    ///   (a stroke does not hop back and forth, nor later than
    ///   [`PLANE_HOP_LEAD_S`] before the hit), and nothing once it is too
    ///   late to change the stroke there or the ball has passed it;
    /// - else the nominal plane, where the ball passes it at least
    ///   [`WINDOW_MARGIN_M`] inside the window;
    /// - else the plane where it passes furthest inside the window, the
    ///   nearest to the nominal of equals.
    ///
    /// On every plane, the nominal one too, the arm must be able to
    /// present a face at the point (the reach map; the window's wide high
    /// corners are beyond it).
    ///
    /// `bounced`: the ball has bounced on the robot's half, so no plane
    /// past its next bounce counts. `Err`: why the nominal plane does not
    /// work, where none does.
    fn choose(
        &self,
        prop: &Propagator,
        state: &crate::physics::BallState,
        t: f64,
        nominal: &Prediction,
        last_x: Option<f64>,
        bounced: bool,
    ) -> Result<(HitPoint, usize), Withheld> {
        let home = self.strike.nominal_plane();
        let at_home = match nominal.hit {
            Some(hit) => stroke::check(self.strike, &hit, hit.t - t)
                .and_then(|()| self.reached(home, &hit).map(|()| (hit, home))),
            None => Err(Withheld::NoHit),
        };
        let roomy = at_home.as_ref().is_ok_and(|(hit, _)| self.margin(hit) >= WINDOW_MARGIN_M);
        if self.planes.len() < 2 || (last_x.is_none() && roomy) {
            return at_home;
        }
        let last = last_x.and_then(|x| self.planes.iter().position(|p| *p == x));
        if last == Some(home) && matches!(at_home, Ok(_) | Err(Withheld::TooSoon)) {
            return at_home;
        }
        let crossings = crate::fit::predict::crossings::<MAX_HITTING_PLANES>(
            prop,
            state,
            t,
            self.planes,
            bounced,
            nominal.bounce.as_ref(),
        );
        let on = |k: usize| -> Result<HitPoint, Withheld> {
            if k == home {
                return at_home.map(|(hit, _)| hit);
            }
            let hit = crossings.get(k).copied().flatten().ok_or(Withheld::NoHit)?;
            stroke::check(self.strike, &hit, hit.t - t)?;
            let p = hit.state.pos;
            if !self.strike.in_window_at(self.planes[k], p.y, p.z) {
                return Err(Withheld::OutsideY);
            }
            self.reached(k, &hit).map(|()| hit)
        };
        if let Some(k) = last {
            // Past that plane already, or too late to change: the stroke
            // there is under way.
            if state.pos.x >= self.planes[k] {
                return Err(Withheld::TooSoon);
            }
            match on(k) {
                Ok(hit) => return Ok((hit, k)),
                Err(Withheld::TooSoon) => return Err(Withheld::TooSoon),
                Err(_) => {}
            }
        }
        // Outwards from the nominal plane (the later of two first): the
        // first of the largest margins.
        let mut best: Option<(HitPoint, usize, f64)> = None;
        for k in self.strike.planes_outwards() {
            if let Ok(hit) = on(k)
                && (last.is_none_or(|l| l == k) || hit.t - t >= PLANE_HOP_LEAD_S)
            {
                let m = self.margin(&hit);
                if best.is_none_or(|(_, _, b)| m > b) {
                    best = Some((hit, k, m));
                }
            }
        }
        best.map(|(hit, k, _)| (hit, k)).ok_or(at_home.err().unwrap_or(Withheld::NoHit))
    }

    /// The arm can present a face at `hit` on plane `k` at the aim's
    /// slowest bat, where the aim uses the reach map.
    fn reached(&self, k: usize, hit: &HitPoint) -> Result<(), Withheld> {
        let p = hit.state.pos;
        let reached = self.reach.get(k).is_none_or(|m| {
            let arm = aim::ArmReach::at(m, p.y, p.z);
            arm.caps[..arm.n].iter().any(|c| *c >= self.strike.aim_bat_speed[0])
        });
        if reached { Ok(()) } else { Err(Withheld::OutOfReach) }
    }

    /// How far inside the window the hitting point lies, m.
    fn margin(&self, hit: &HitPoint) -> f64 {
        let (p, s) = (hit.state.pos, self.strike);
        (p.y - s.window_y[0]).min(s.window_y[1] - p.y).min(p.z - s.window_z[0]).min(s.window_z[1] - p.z)
    }
}

/// This ball's drag before its bounce, as a multiplier of the
/// calibration's: what its batches read (the whole flight model over the
/// window, [`smooth`]), else the cubic's deceleration along the flight
/// ([`session::drag_from_flight`], which reads 2–5 % low: a session learning
/// from it ended at 0.976 of our own world's air and 1.466 of heavy-air's
/// 1.537, from the batches at 1.000 and 1.536).
fn own_drag(track: &Track, prop: &Propagator, min_samples: usize) -> Option<f64> {
    if track.smoothed {
        Some(track.prop.flight.k_d() / prop.flight.k_d())
    } else {
        session::drag_from_flight(&track.window, &prop.flight, min_samples)
    }
}

/// The flight a ball flies with before its batch has read it: the
/// calibration's, with the session's drag weighed against the ball's own
/// (one cubic over its window) where learning is on.
fn ball_flight(
    prop: &Propagator,
    session: &LearnedSession,
    cfg: &EstimatorConfig,
    window: &[Sample],
) -> crate::physics::FlightModel {
    if !cfg.learn.enabled {
        return prop.flight;
    }
    let own = session::drag_from_flight(window, &prop.flight, cfg.learn.min_samples);
    prop.flight.scaled(FlightScales { drag: cfg.learn.ball_drag(&session.drag, own), lift: 1.0 })
}

/// Starts a batch over the track's window (pre-bounce) from the filter's
/// state, against the session's air weighed with this ball's own cubic
/// reading (the drag's prior).
fn start_batch(track: &mut Track, prop: &Propagator, session: &LearnedSession, cfg: &EstimatorConfig, drag_std: f64) {
    let flight = ball_flight(prop, session, cfg, &track.window);
    let priors = smooth::Priors {
        sigma: cfg.noise.measurement,
        along_std: cfg.spin_prior_along_velocity,
        spin_std: SPIN_PRIOR_STD,
        drag_std,
    };
    let prop = Propagator { flight, ..track.prop };
    track.batch = smooth::Batch::start(&prop, &track.window, &track.ekf.state(), &priors);
    track.batch_from = track.window.len();
}

/// Advances the track's batch ([`smooth::Batch`]) by a bounded share, and
/// when it is done hands what it found to the filter: the spin it read
/// (constant in flight) with the uncertainty the window leaves it, and the
/// drag for the rest of the flight. The filter keeps its position and
/// velocity, which its latest samples set: the batch's, flown on from its
/// window's end, would be millimetres off them, and the gate would take
/// the next samples for another ball.
fn advance_batch(track: &mut Track, samples: usize) {
    let Some(batch) = &mut track.batch else { return };
    let smooth::Progress::Done(found) = batch.advance(&track.window, samples) else { return };
    let given = batch.prop.flight;
    track.batch = None;
    let Some(found) = found else { return };
    if found.state.spin.iter().all(|v| v.is_finite()) {
        for k in 0..3 {
            track.ekf.x[6 + k] = found.state.spin[k];
        }
        // The filter's own spin covariance, from its linearisations, strays
        // from the window's (σ 0.5–2× of it, p10–p90, on our own flights);
        // at the bounce it sets how far the first samples after it move
        // the velocity.
        if let Some(cov) = &found.spin_cov {
            track.ekf.set_spin_covariance(cov);
        }
        track.prop.flight = given.scaled(FlightScales { drag: found.drag, lift: 1.0 });
        track.smoothed = true;
    }
}

/// σ of ln(spin) at the contact ([`ekf::EkfNoise::bounce_spin_share`])
/// for a bounce flown again because its first samples surprised the
/// filter: the spin the table met is then far from the flight's reading
/// (a saturated flight of real balls shows a third of fast spin to all
/// of it, and a ball's own lift strays by ±25 %). One: ×2.7 at 1σ.
pub(crate) const SURPRISE_SHARE: f64 = 1.0;
/// Samples after the bounce within which a rejected one has the bounce
/// flown again ([`rescue_bounce`]): 4 at 150 Hz, 27 ms.
const RESCUE_WITHIN: usize = 4;

/// `ekf` with the bounce's spin share at least [`SURPRISE_SHARE`], flown
/// through `samples`; `None` where the gate rejects one of them.
fn flown_wide<'a>(mut ekf: Ekf, prop: &Propagator, samples: impl Iterator<Item = &'a Sample>) -> Option<Ekf> {
    ekf.noise.bounce_spin_share = ekf.noise.bounce_spin_share.max(SURPRISE_SHARE);
    for s in samples {
        ekf.predict(prop, s.t);
        if let Update::Rejected { .. } = ekf.update(&s.pos) {
            return None;
        }
    }
    Some(ekf)
}

/// A sample rejected just after the bounce, where the filter took the
/// first ones with the spin its flight showed and the kick was larger (a
/// topspin ball whose spin the flight read at a third): the bounce flown
/// again from the filter before it with the spin's size free
/// ([`SURPRISE_SHARE`]), through the samples since and this one. Where
/// all of them pass the gate the track goes on with that filter, the
/// sample taken (`Some`), rather than being lost and its bounce with it
/// (the session learned nothing from the fast topspin balls it most
/// needed). Once per bounce, bounded work.
fn rescue_bounce(track: &mut Track, sample: &Sample, hit_plane_x: f64) -> Option<()> {
    let pre = track.pre_bounce?;
    if track.ekf.bounces != 1
        || track.after.len() > RESCUE_WITHIN
        || track.ekf.noise.bounce_spin_share >= SURPRISE_SHARE
        || !track.rejects.is_empty()
    {
        return None;
    }
    let wide = flown_wide(pre, &track.prop, track.after.iter().chain(std::iter::once(sample)))?;
    if wide.bounces != 1 {
        return None;
    }
    track.ekf = wide;
    track.last_t = sample.t;
    if sample.pos.x < hit_plane_x {
        let _ = track.after.push(*sample);
    }
    Some(())
}

/// Most distance along x flown over, either way, from a ball's samples
/// to the net ([`speed_at_net`]), m: a launcher stands at most 2 m behind it.
const TO_NET_MAX: f64 = 3.0;
/// The step along x of that flight, m.
const TO_NET_STEP: f64 = 0.2;

/// The speed `state` has where it crosses the net (x = 0), m/s: its
/// velocity flown there (or back) under the filter's own flight model, in
/// midpoint steps along x (dv/dx = a(v)/v_x; the acceleration depends on
/// the velocity and the spin alone). The same point of every flight, so
/// that balls the tracker first saw 1 m apart (12 % slower at 10 m/s) are
/// alike; read again from the filter as the ball nears the net, the
/// nearer the better. Bounded: at most 15 steps.
fn speed_at_net(state: &crate::physics::BallState, flight: &crate::physics::FlightModel) -> f64 {
    let mut vel = state.vel;
    let dx = (-state.pos.x).clamp(-TO_NET_MAX, TO_NET_MAX);
    if !(vel.x.abs() > 0.5 && dx.is_finite()) {
        return vel.norm();
    }
    let n = (dx.abs() / TO_NET_STEP).ceil().max(1.0);
    let h = dx / n;
    for _ in 0..n as usize {
        let half = vel + flight.accel(&vel, &state.spin) * (0.5 * h / vel.x);
        if half.x.abs() <= 0.5 {
            break;
        }
        vel += flight.accel(&half, &state.spin) * (h / half.x);
        if vel.x.abs() <= 0.5 {
            break;
        }
    }
    vel.norm()
}

/// The paper's fit over the pre-bounce window, imposed on the EKF's spin.
fn refit_spin(track: &mut Track, prop: &Propagator) {
    if track.window.len() < ACQUIRE_LEN {
        return;
    }
    let Some(cubic) = Cubic::fit(track.window.iter()) else { return };
    let Some(m) = magnus::solve(&cubic, track.window.iter().map(|s| s.t), &prop.flight) else { return };
    let spin = prop.flight.spin_from_linear(&m.spin_linear, m.mean_speed).unwrap_or(m.spin_linear);
    for k in 0..3 {
        track.ekf.x[6 + k] = spin[k];
    }
    for i in 0..9 {
        for j in 6..9 {
            if i != j {
                track.ekf.p[(i, j)] = 0.0;
                track.ekf.p[(j, i)] = 0.0;
            }
        }
    }
    for j in 6..9 {
        track.ekf.p[(j, j)] = 25.0 * 25.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{BallState, Event, StopAt};

    #[test]
    fn a_balls_speed_at_the_net_is_the_same_wherever_the_tracker_first_saw_it() {
        let prop = Calibration::default_cell().propagator();
        // Topspin and backspin from behind the opponent's end line.
        for (vel, spin) in [(Vec3::new(9.0, -0.3, 1.8), 400.0), (Vec3::new(6.0, 0.2, 1.2), -250.0)] {
            let mut ball = BallState::new(Vec3::new(-1.8, 0.1, 0.35), vel, Vec3::new(0.0, spin, 0.0));
            let mut t = 0.0;
            let mut seen = Vec::new();
            for x in [-1.6, -1.2, -0.8, -0.4, 0.0] {
                let event = prop.advance(&mut ball, &mut t, &StopAt { t_max: 1.0, hit_plane_x: Some(x), net: false });
                assert!(matches!(event, Event::HitPlane { .. }) && ball.pos.z > 0.2, "{spin}: {event:?} {ball:?}");
                seen.push(ball);
            }
            let truth = seen[4].vel.norm();
            // The speed where the tracker first saw it strays by 8–15 %.
            assert!(seen[0].vel.norm() / truth > 1.08, "{spin}: {} against {truth}", seen[0].vel.norm());
            for s in &seen {
                let v = speed_at_net(s, &prop.flight);
                assert!((v / truth - 1.0).abs() < 0.002, "{spin}, from x {:.1}: {v:.3} against {truth:.3}", s.pos.x);
            }
        }
    }
}
