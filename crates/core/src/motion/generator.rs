//! The stroke generator: reach the hitting pose at the hitting time with the
//! bat velocity, follow through, return home — one setpoint per cycle,
//! re-planned online whenever a refined plan arrives.
//!
//! It uses Ruckig (`rsruckig`, the field-standard online trajectory
//! generator): from the current commanded state (position, velocity,
//! acceleration) to a target state under per-axis velocity, acceleration
//! and jerk limits, with all six axes time-synchronised. The hitting time is
//! met with Ruckig's `minimum_duration`: the time-optimal profile is
//! stretched to end exactly at the hit. If the hit cannot be reached in time
//! the profile ends as early as the limits allow and the lateness is
//! reported ([`StrokeGenerator::late_by`]). Re-planning starts from the
//! state the last setpoint was sampled from, so the commanded path stays
//! continuous in velocity and acceleration across plan changes.
//!
//! Ruckig is only asked to calculate when the target changes (a new plan,
//! or a phase change); other cycles sample the stored trajectory. With six
//! stack-allocated DOFs it does not allocate on success (the counting
//! allocator test covers it); its error path formats a message, which
//! allocates — plans are sanitised first so that path stays unused.
//!
//! Plans are checked here: non-finite values, a hit in the past or too far
//! ahead, or a hit far outside the workspace are rejected; a hit slightly
//! outside is pulled in (with room to brake from the bat velocity), the bat
//! speed and orientation are clamped to the cell's limits.
//!
//! Every stroke is then checked in joint space before it is taken: the
//! path is sampled ([`JOINT_SAMPLES`] points to the hit), each point solved
//! by the arm's inverse kinematics nearest the previous one (the
//! configuration stays continuous), and the joints checked against the
//! software limit switches, the singular wrist and [`JOINT_LIMIT_FRACTION`]
//! of the axis speeds and accelerations. A stroke too fast for the axes is
//! planned again with the Cartesian limits (and the bat speed) scaled down
//! by what it lacked, up to [`JOINT_RETRIES`] times; one that still breaks
//! a limit, cannot be solved, or would arrive more than [`MAX_LATE_S`] late
//! is refused with the reason ([`PlanRejected::key`]) and the current
//! motion goes on (home, or the stroke already under way). Follow-through
//! and return run at [`CALM_LIMIT_FRACTION`] of the Cartesian limits, where
//! no axis reaches its limit anywhere in the workspace.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use rsruckig::prelude::*;

use super::limits::GENERATOR_LIMIT_FRACTION;
use super::{MotionLimits, Pose6};
use crate::kinematics::{AXES, Joints, LimitKind, LimitViolation, Pose, Unreachable};
use crate::plan::StrikePlan;
use crate::time::Instant;

/// How far ahead a hit may be planned, s.
pub(crate) const MAX_PLAN_HORIZON_S: f64 = 5.0;
/// How far outside the workspace a hit may be and still be pulled in, m.
pub(crate) const MAX_OUTSIDE_M: f64 = 0.10;
/// Extra room kept between a hit with velocity and the box walls, m.
pub(crate) const WALL_MARGIN_M: f64 = 0.01;

/// Arrival this much after the hitting time counts as on time, s.
pub(crate) const LATE_TOLERANCE_S: f64 = 0.0005;
/// A refinement of the same ball (within this of the current target in
/// time, s, and per axis, m) that would arrive late is weighed against the
/// current, on-time stroke: near the hit the axes are in their final,
/// limit-bound motion, and Ruckig answers even a millimetre's change with
/// arriving 20–35 ms late. Arriving `late_by` late misses a ball crossing
/// at [`BALL_SPEED_AT_HIT`] by about `late_by × speed`; keeping the old
/// stroke misses by the refinement's change. The smaller miss wins. Early
/// refinements arrive on time and are always taken.
pub(crate) const KEEP_MAX_DT_S: f64 = 0.010;
pub(crate) const KEEP_MAX_DP_M: f64 = 0.15;
/// Typical ball speed at the hitting plane (after the bounce), m/s.
pub(crate) const BALL_SPEED_AT_HIT: f64 = 4.0;
/// Points of the path to the hit solved in joint space.
pub const JOINT_SAMPLES: usize = 32;
/// Share of the axis speed limits a stroke may use (the rest absorbs the
/// sampling and the refinements to come).
pub const JOINT_SPEED_FRACTION: f64 = 0.85;
/// Share of the axis acceleration limits, lower: differences over the
/// samples flatten the jerk-limited peaks.
pub const JOINT_ACCELERATION_FRACTION: f64 = 0.7;
/// A refinement within this of the checked stroke (m at the hit, and s)
/// whose check left this much room (share of the allowed) is not checked
/// again: the check costs tens of µs in the RSI thread.
pub const RECHECK_DP_M: f64 = 0.02;
/// See [`RECHECK_DP_M`].
pub const RECHECK_DT_S: f64 = 0.005;
/// See [`RECHECK_DP_M`].
pub const RECHECK_ROOM: f64 = 0.85;
/// Re-plans with lower Cartesian limits for a stroke too fast for the axes.
pub const JOINT_RETRIES: usize = 2;
/// A new ball's stroke arriving later than this is refused, s (the bat
/// would be ~4 cm behind a ball crossing at 4 m/s).
pub const MAX_LATE_S: f64 = 0.010;
/// Share of the Cartesian limits for follow-through and return.
pub const CALM_LIMIT_FRACTION: f64 = 0.5;
/// Duration nudges tried when Ruckig misses the hitting time, s.
const RETRY_NUDGES_S: [f64; 4] = [-0.0003, 0.0003, -0.0007, 0.0007];

/// What the generator is doing.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Phase {
    /// At rest (home, or where a failure left it).
    Hold,
    /// Towards the hitting pose, arriving at the hitting time.
    Approach,
    /// After the hit: keep moving, braking to rest.
    FollowThrough,
    /// Back to home.
    Return,
}

/// Why a plan was not taken.
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlanRejected {
    /// A value is NaN or infinite.
    #[error("plan has non-finite values")]
    NonFinite,
    /// The hitting time is not after the current setpoint time.
    #[error("hit time is in the past")]
    HitInPast,
    /// The hitting time is beyond [`MAX_PLAN_HORIZON_S`].
    #[error("hit time too far ahead")]
    TooFarAhead,
    /// The hitting point is more than [`MAX_OUTSIDE_M`] outside the box.
    #[error("hitting point outside the workspace")]
    OutsideWorkspace,
    /// Ruckig found no trajectory (should not happen after sanitising).
    #[error("no trajectory to the hitting pose")]
    NoTrajectory,
    /// A point of the stroke has no joint solution.
    #[error("stroke out of the arm's reach")]
    OutOfReach,
    /// The stroke breaks an axis limit (even slowed down).
    #[error("stroke breaks {0}")]
    Joint(LimitViolation),
    /// The stroke (slowed down to the axes' limits) arrives too late.
    #[error("stroke would arrive too late")]
    TooLate,
}

impl PlanRejected {
    /// A short key for counting refusals by reason.
    pub fn key(&self) -> &'static str {
        match self {
            PlanRejected::NonFinite => "non_finite",
            PlanRejected::HitInPast => "hit_in_past",
            PlanRejected::TooFarAhead => "too_far_ahead",
            PlanRejected::OutsideWorkspace => "outside_workspace",
            PlanRejected::NoTrajectory => "no_trajectory",
            PlanRejected::OutOfReach => "out_of_reach",
            PlanRejected::Joint(v) => match v.kind {
                LimitKind::Position => "joint_position_limit",
                LimitKind::SingularWrist => "singular_wrist",
                LimitKind::Speed => "joint_speed",
                LimitKind::Acceleration => "joint_acceleration",
            },
            PlanRejected::TooLate => "too_late",
        }
    }
}

/// The accepted target of a plan, in B.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct StrokeTarget {
    /// The `seq` of the plan this target came from.
    pub seq: u32,
    /// When the TCP should be at `pose`, s on the `Instant` clock.
    pub hit_time: f64,
    /// TCP pose at the hit (m, rad), pulled into the workspace if needed.
    pub pose: Pose6,
    /// TCP velocity at the hit (m/s; rotational components are 0), speed
    /// clamped to the cell's bat-speed limit.
    pub velocity: Pose6,
    /// Whether the plan had to be clamped to fit the cell.
    pub clamped: bool,
}

type Otg = Ruckig<6, IgnoreErrorHandler>;

/// What [`StrokeGenerator::joint_check`] found.
enum JointTrouble {
    /// Refuse the plan.
    Rejected(PlanRejected),
    /// Too fast for the axes: the largest speed and acceleration shares
    /// of the allowed (> 1 where too fast), and the worst violation.
    TooFast { speed: f64, acceleration: f64, violation: LimitViolation },
}

/// The online stroke generator (see the module doc).
#[derive(Debug)]
pub struct StrokeGenerator {
    lim: MotionLimits,
    otg: Otg,
    input: InputParameter<6>,
    traj: Trajectory<6>,
    spare: Trajectory<6>,
    /// Start of `traj`, s (the `Instant` domain).
    t0: f64,
    phase: Phase,
    target: Option<StrokeTarget>,
    /// The last sampled state and its time.
    p: Pose6,
    v: Pose6,
    a: Pose6,
    t_last: f64,
    late_by: f64,
    /// The joints at `p` (kept continuous from home).
    q: Joints,
    /// The last full joint check's largest share of the allowed.
    checked_room: f64,
    /// Ruckig calculations done.
    pub calculations: u64,
    /// Ruckig calculations that failed.
    pub failures: u64,
    /// Refinements not taken because they would arrive late.
    pub kept: u64,
}

fn secs(t: Instant) -> f64 {
    t.as_secs_f64()
}

impl StrokeGenerator {
    /// A generator at rest at `start`, at time `now`.
    pub fn new(lim: MotionLimits, now: Instant, start: Pose6) -> Self {
        let home_joints = lim.home_joints;
        let mut input = InputParameter::new(None);
        for i in 0..6 {
            input.max_velocity[i] = lim.vmax[i] * GENERATOR_LIMIT_FRACTION;
            input.max_acceleration[i] = lim.amax[i] * GENERATOR_LIMIT_FRACTION;
            input.max_jerk[i] = lim.jmax[i] * GENERATOR_LIMIT_FRACTION;
        }
        let mut g = StrokeGenerator {
            otg: Ruckig::new(None, lim.dt),
            traj: Trajectory::new(None),
            spare: Trajectory::new(None),
            input,
            lim,
            t0: 0.0,
            phase: Phase::Hold,
            target: None,
            p: start,
            v: [0.0; 6],
            a: [0.0; 6],
            t_last: 0.0,
            late_by: 0.0,
            q: home_joints,
            checked_room: f64::INFINITY,
            calculations: 0,
            failures: 0,
            kept: 0,
        };
        g.reset(now, start);
        g
    }

    /// Restarts at rest at `start` (e.g. the robot's pose at RSI start) and
    /// returns home from there.
    pub fn reset(&mut self, now: Instant, start: Pose6) {
        self.p = start;
        self.v = [0.0; 6];
        self.a = [0.0; 6];
        self.t_last = secs(now);
        self.target = None;
        self.late_by = 0.0;
        self.go_home();
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The accepted target, if a stroke is under way.
    pub fn target(&self) -> Option<&StrokeTarget> {
        self.target.as_ref()
    }

    /// How late the current stroke will reach its hitting pose, s (0 if on
    /// time).
    pub fn late_by(&self) -> f64 {
        self.late_by
    }

    /// The limits in use.
    pub fn limits(&self) -> &MotionLimits {
        &self.lim
    }

    /// Checks and converts a plan to a target in B (see the module doc).
    pub(crate) fn target_of(&self, plan: &StrikePlan) -> Result<StrokeTarget, PlanRejected> {
        let lim = &self.lim;
        let o = plan.orientation;
        let finite = plan.position.iter().all(|x| x.is_finite())
            && plan.velocity.iter().all(|x| x.is_finite())
            && [o.a, o.b, o.c].iter().all(|x| x.is_finite());
        if !finite {
            return Err(PlanRejected::NonFinite);
        }
        let hit_time = secs(plan.hit_time);
        if hit_time <= self.t_last {
            return Err(PlanRejected::HitInPast);
        }
        if hit_time - self.t_last > MAX_PLAN_HORIZON_S {
            return Err(PlanRejected::TooFarAhead);
        }
        let p = lim.point_t_to_b(plan.position);
        let mut v = lim.rotate_t_to_b(plan.velocity);
        let mut clamped = false;
        let speed = v.norm();
        if speed > lim.max_bat_speed {
            v *= lim.max_bat_speed / speed;
            clamped = true;
        }
        let mut pose = [0.0; 6];
        let mut vel = [0.0; 6];
        for i in 0..3 {
            if p[i] < lim.lo[i] - MAX_OUTSIDE_M || p[i] > lim.hi[i] + MAX_OUTSIDE_M {
                return Err(PlanRejected::OutsideWorkspace);
            }
            // Room to brake from v[i] (jerk-limited) before the wall.
            let (a, j) = (lim.amax[i] * GENERATOR_LIMIT_FRACTION, lim.jmax[i] * GENERATOR_LIMIT_FRACTION);
            let mut vi = v[i];
            let mut margin = vi * vi / (2.0 * a) + vi.abs() * a / j + WALL_MARGIN_M;
            if lim.lo[i] + margin > lim.hi[i] - margin {
                vi = 0.0;
                margin = WALL_MARGIN_M;
            }
            let lo = if vi < 0.0 { lim.lo[i] + margin } else { lim.lo[i] + WALL_MARGIN_M };
            let hi = if vi > 0.0 { lim.hi[i] - margin } else { lim.hi[i] - WALL_MARGIN_M };
            let pi = p[i].clamp(lo, hi.max(lo));
            if pi != p[i] || vi != v[i] {
                clamped = true;
            }
            pose[i] = pi;
            vel[i] = vi;
        }
        let abc = lim.orientation_t_to_b(o);
        for i in 0..3 {
            let k = 3 + i;
            let x = abc[i].clamp(lim.lo[k], lim.hi[k]);
            if x != abc[i] {
                clamped = true;
            }
            pose[k] = x;
        }
        Ok(StrokeTarget { seq: plan.seq, hit_time, pose, velocity: vel, clamped })
    }

    /// Takes a new plan: re-plans towards it from the current state. A plan
    /// with the same `seq` as the current target is ignored.
    pub fn set_plan(&mut self, plan: &StrikePlan) -> Result<&StrokeTarget, PlanRejected> {
        if let Some(t) = &self.target
            && t.seq == plan.seq
            && self.phase == Phase::Approach
        {
            return Ok(self.target.as_ref().expect("checked"));
        }
        let mut target = self.target_of(plan)?;
        let duration = target.hit_time - self.t_last;
        // Keep the current stroke aside: a refinement that can no longer be
        // met on time (the axes are already in their final, limit-bound
        // acceleration) but differs only a little is not worth arriving late.
        std::mem::swap(&mut self.traj, &mut self.spare);
        let (old_t0, old_target, old_phase) = (self.t0, self.target, self.phase);
        let restore = |g: &mut Self| {
            std::mem::swap(&mut g.traj, &mut g.spare);
            g.t0 = old_t0;
            g.set_limit_scale(1.0, 1.0);
        };
        // Solve the stroke, then check it in joint space; too fast for the
        // axes: again with the Cartesian limits scaled down.
        let q0 = match self.lim.arm.inverse_near(&Pose::from_pose6(&self.p), &self.q) {
            Ok(q) => q,
            Err(_) => self.q,
        };
        self.q = q0;
        let (mut v_scale, mut a_scale) = (1.0, 1.0);
        let mut attempt = 0;
        loop {
            self.set_limit_scale(v_scale, a_scale);
            if !self.calculate_on_time(&target, duration) {
                restore(self);
                return Err(PlanRejected::NoTrajectory);
            }
            let small_refinement = attempt == 0
                && old_phase == Phase::Approach
                && self.checked_room < RECHECK_ROOM
                && old_target.is_some_and(|old| {
                    (old.hit_time - target.hit_time).abs() <= RECHECK_DT_S
                        && (0..3).map(|i| (old.pose[i] - target.pose[i]).powi(2)).sum::<f64>().sqrt() <= RECHECK_DP_M
                });
            if small_refinement {
                break;
            }
            match self.joint_check(q0) {
                Ok(room) => {
                    self.checked_room = room;
                    break;
                }
                Err(JointTrouble::TooFast { .. }) if !self.lim.check_joint_rates => break,
                Err(JointTrouble::Rejected(r)) => {
                    restore(self);
                    return Err(r);
                }
                Err(JointTrouble::TooFast { speed, acceleration, violation }) => {
                    if attempt == JOINT_RETRIES {
                        restore(self);
                        return Err(PlanRejected::Joint(violation));
                    }
                    attempt += 1;
                    v_scale /= speed.max(1.0);
                    a_scale /= acceleration.max(1.0);
                    for x in &mut target.velocity[..3] {
                        *x /= speed.max(1.0);
                    }
                    target.clamped = true;
                }
            }
        }
        self.set_limit_scale(1.0, 1.0);
        let late_by = (self.traj.get_duration() - duration).max(0.0);
        let refinement = old_phase == Phase::Approach
            && old_target.is_some_and(|old| (old.hit_time - target.hit_time).abs() <= KEEP_MAX_DT_S);
        if late_by > MAX_LATE_S && !refinement {
            restore(self);
            return Err(PlanRejected::TooLate);
        }
        if late_by > LATE_TOLERANCE_S
            && old_phase == Phase::Approach
            && let Some(old) = old_target
            && old.hit_time > self.t_last
            && (old.hit_time - target.hit_time).abs() <= KEEP_MAX_DT_S
            && (0..3).all(|i| (old.pose[i] - target.pose[i]).abs() <= KEEP_MAX_DP_M)
            && (0..3).map(|i| (old.pose[i] - target.pose[i]).powi(2)).sum::<f64>().sqrt() <= late_by * BALL_SPEED_AT_HIT
        {
            restore(self);
            self.kept += 1;
            self.late_by = 0.0;
            return Ok(self.target.as_ref().expect("old target"));
        }
        self.late_by = late_by;
        self.phase = Phase::Approach;
        self.target = Some(target);
        Ok(self.target.as_ref().expect("just set"))
    }

    /// A trajectory to `target` ending `duration` from now, nudged where
    /// Ruckig's synchronisation misses it; false if Ruckig fails.
    fn calculate_on_time(&mut self, target: &StrokeTarget, duration: f64) -> bool {
        if !self.calculate(&target.pose, &target.velocity, Some(duration)) {
            return false;
        }
        // Ruckig's time-synchronisation step sometimes finds no profile for
        // exactly this duration (numerically, not physically) and returns
        // the end of a later interval. Nudging the duration by a fraction of
        // a millisecond finds a profile in nearly all those cases.
        for nudge in RETRY_NUDGES_S {
            if self.traj.get_duration() - duration <= LATE_TOLERANCE_S {
                break;
            }
            self.calculate(&target.pose, &target.velocity, Some(duration + nudge));
        }
        true
    }

    /// Ruckig's limits: the cell's (times the generator's fraction) scaled
    /// by `v` (velocity) and `a` (acceleration and jerk).
    fn set_limit_scale(&mut self, v: f64, a: f64) {
        for i in 0..6 {
            self.input.max_velocity[i] = self.lim.vmax[i] * GENERATOR_LIMIT_FRACTION * v;
            self.input.max_acceleration[i] = self.lim.amax[i] * GENERATOR_LIMIT_FRACTION * a;
            self.input.max_jerk[i] = self.lim.jmax[i] * GENERATOR_LIMIT_FRACTION * a;
        }
    }

    /// The new trajectory in joint space from `q0` (the joints now): each of
    /// [`JOINT_SAMPLES`] points solved nearest the previous, checked against
    /// the software limits and the singular wrist, and the speeds and
    /// accelerations between them against [`JOINT_LIMIT_FRACTION`] of the
    /// axis limits. Bounded work, no allocation. `Ok` carries the largest
    /// share of the allowed speed or acceleration.
    fn joint_check(&self, q0: Joints) -> Result<f64, JointTrouble> {
        let arm = &self.lim.arm;
        let lim = &arm.limits;
        let h = self.traj.get_duration() / JOINT_SAMPLES as f64;
        if h <= 0.0 {
            return Ok(0.0);
        }
        // The joint speed now: from where the bat was one step ago.
        let before: Pose6 = core::array::from_fn(|i| self.p[i] - self.v[i] * h);
        let mut qd_prev = match arm.inverse_near(&Pose::from_pose6(&before), &q0) {
            Ok(q) => Some(core::array::from_fn(|i| (q0.0[i] - q.0[i]) / h)),
            Err(_) => None,
        };
        let mut q_prev = q0;
        let (mut speed, mut acceleration) = (0.0f64, 0.0f64);
        let mut worst: Option<LimitViolation> = None;
        let mut worst_share = 0.0;
        for k in 1..=JOINT_SAMPLES {
            let p = self.pose_at(self.t0 + k as f64 * h);
            let q = match arm.inverse_near(&Pose::from_pose6(&p), &q_prev) {
                Ok(q) => q,
                Err(Unreachable::OutOfReach) => return Err(JointTrouble::Rejected(PlanRejected::OutOfReach)),
                Err(Unreachable::Limit(v)) => return Err(JointTrouble::Rejected(PlanRejected::Joint(v))),
            };
            if let Err(v) = lim.check_position(&q) {
                return Err(JointTrouble::Rejected(PlanRejected::Joint(v)));
            }
            let qd: [f64; AXES] = core::array::from_fn(|i| (q.0[i] - q_prev.0[i]) / h);
            for i in 0..AXES {
                let share = qd[i].abs() / (lim.speed[i] * JOINT_SPEED_FRACTION);
                speed = speed.max(share);
                if share > 1.0 && share > worst_share {
                    worst_share = share;
                    worst = Some(LimitViolation {
                        axis: crate::kinematics::Axis::ALL[i],
                        kind: LimitKind::Speed,
                        value: qd[i],
                        limit: lim.speed[i],
                    });
                }
                if let Some(prev) = qd_prev {
                    let qdd = (qd[i] - prev[i]) / h;
                    let share = qdd.abs() / (lim.acceleration[i] * JOINT_ACCELERATION_FRACTION);
                    acceleration = acceleration.max(share);
                    if share > 1.0 && share > worst_share {
                        worst_share = share;
                        worst = Some(LimitViolation {
                            axis: crate::kinematics::Axis::ALL[i],
                            kind: LimitKind::Acceleration,
                            value: qdd,
                            limit: lim.acceleration[i],
                        });
                    }
                }
            }
            q_prev = q;
            qd_prev = Some(qd);
        }
        match worst {
            None => Ok(speed.max(acceleration)),
            Some(violation) => Err(JointTrouble::TooFast { speed, acceleration, violation }),
        }
    }

    /// The new trajectory's pose at absolute time `t`.
    fn pose_at(&self, t: f64) -> Pose6 {
        if self.traj.get_duration() <= 0.0 {
            return self.p;
        }
        let mut p = DataArrayOrVec::Stack([0.0; 6]);
        let mut section = None;
        self.traj.at_time((t - self.t0).max(0.0), &mut Some(&mut p), &mut None, &mut None, &mut None, &mut section);
        core::array::from_fn(|i| p[i])
    }

    /// Replaces the state the next plan starts from (after the safety
    /// filter changed a setpoint), and re-plans the current phase from it.
    pub(crate) fn override_state(&mut self, p: Pose6, v: Pose6, a: Pose6) {
        self.p = p;
        self.v = v;
        self.a = a;
        match (self.phase, self.target) {
            (Phase::Approach, Some(t)) if t.hit_time > self.t_last => {
                if !self.calculate(&t.pose, &t.velocity, Some(t.hit_time - self.t_last)) {
                    self.go_home();
                }
            }
            (Phase::FollowThrough, Some(_)) => {
                let rest = self.p;
                if !self.calculate_calm(&rest) {
                    self.go_home();
                }
            }
            _ => self.go_home(),
        }
    }

    /// The setpoint for time `t` (the time the robot will be there).
    pub fn next(&mut self, t: Instant) -> Pose6 {
        let t = secs(t);
        // Phase changes at the end of each segment (at most three chain).
        for _ in 0..3 {
            let end = self.t0 + self.traj.get_duration();
            if t < end || self.phase == Phase::Hold {
                break;
            }
            self.sample_into_state(end);
            match self.phase {
                Phase::Approach => {
                    let v = self.v;
                    let lim = &self.lim;
                    let mut rest = [0.0; 6];
                    for i in 0..6 {
                        let m = if i < 3 { WALL_MARGIN_M } else { 0.0 };
                        rest[i] = (self.p[i] + v[i] * lim.follow_through).clamp(lim.lo[i] + m, lim.hi[i] - m);
                    }
                    if self.calculate_calm(&rest) {
                        self.phase = Phase::FollowThrough;
                    } else {
                        self.go_home();
                    }
                }
                Phase::FollowThrough => self.go_home(),
                Phase::Return => {
                    self.phase = Phase::Hold;
                    self.target = None;
                }
                Phase::Hold => {}
            }
        }
        self.sample_into_state(t);
        self.p
    }

    /// To rest at `pos` at [`CALM_LIMIT_FRACTION`] of the limits, slower
    /// still where the joint check finds the axes too fast (near a
    /// stretched elbow a small Cartesian motion is a fast joint motion).
    fn calculate_calm(&mut self, pos: &Pose6) -> bool {
        let q0 = self.lim.arm.inverse_near(&Pose::from_pose6(&self.p), &self.q).unwrap_or(self.q);
        self.q = q0;
        let (mut v, mut a) = (CALM_LIMIT_FRACTION, CALM_LIMIT_FRACTION);
        let mut ok = false;
        for _ in 0..=JOINT_RETRIES + 1 {
            self.set_limit_scale(v, a);
            ok = self.calculate(pos, &[0.0; 6], None);
            match self.joint_check(q0) {
                Err(JointTrouble::TooFast { speed, acceleration, .. }) if ok && self.lim.check_joint_rates => {
                    v /= speed.max(1.0);
                    a /= acceleration.max(1.0);
                }
                _ => break,
            }
        }
        self.set_limit_scale(1.0, 1.0);
        ok
    }

    fn go_home(&mut self) {
        let home = self.lim.home;
        if self.calculate_calm(&home) {
            self.phase = Phase::Return;
        } else {
            self.phase = Phase::Hold;
        }
        self.target = None;
    }

    /// Samples the trajectory at absolute time `t` into the state. An empty
    /// trajectory (every axis at rest at its target) leaves the position
    /// as it is: Ruckig samples its disabled axes as zeros.
    fn sample_into_state(&mut self, t: f64) {
        if self.traj.get_duration() <= 0.0 {
            self.v = [0.0; 6];
            self.a = [0.0; 6];
            self.t_last = t;
            return;
        }
        let mut p = DataArrayOrVec::Stack([0.0; 6]);
        let mut v = DataArrayOrVec::Stack([0.0; 6]);
        let mut a = DataArrayOrVec::Stack([0.0; 6]);
        let mut section = None;
        let dt = (t - self.t0).max(0.0);
        self.traj.at_time(dt, &mut Some(&mut p), &mut Some(&mut v), &mut Some(&mut a), &mut None, &mut section);
        for i in 0..6 {
            self.p[i] = p[i];
            self.v[i] = v[i];
            self.a[i] = a[i];
        }
        self.t_last = t;
    }

    /// A new trajectory from the state at `t_last` to the target; false
    /// (and the old trajectory kept) if Ruckig fails.
    fn calculate(&mut self, pos: &Pose6, vel: &Pose6, min_duration: Option<f64>) -> bool {
        for i in 0..6 {
            self.input.current_position[i] = self.p[i];
            self.input.current_velocity[i] = self.v[i];
            self.input.current_acceleration[i] = self.a[i];
            self.input.target_position[i] = pos[i];
            self.input.target_velocity[i] = vel[i];
            self.input.target_acceleration[i] = 0.0;
            // An axis already resting at its target is left out: Ruckig's
            // time synchronisation can fail on such (numerically) empty
            // moves and return a later duration for all axes.
            let resting =
                (pos[i] - self.p[i]).abs() < 1e-7 && self.v[i].abs() < 1e-7 && self.a[i].abs() < 1e-6 && vel[i] == 0.0;
            self.input.enabled[i] = !resting;
            if resting {
                self.input.current_position[i] = pos[i];
                self.input.current_velocity[i] = 0.0;
                self.input.current_acceleration[i] = 0.0;
            }
        }
        self.input.minimum_duration = min_duration;
        self.calculations += 1;
        let ok = matches!(self.otg.calculate(&self.input, &mut self.traj), Ok(RuckigResult::Working));
        if ok {
            self.t0 = self.t_last;
        } else {
            self.failures += 1;
            // Hold still where we are: a trajectory of zero length.
            for i in 0..6 {
                self.input.target_position[i] = self.p[i];
                self.input.target_velocity[i] = 0.0;
                self.input.current_velocity[i] = 0.0;
                self.input.current_acceleration[i] = 0.0;
            }
            self.input.minimum_duration = None;
            let _ = self.otg.calculate(&self.input, &mut self.traj);
            self.t0 = self.t_last;
        }
        ok
    }
}
