//! The stroke generator: reach the hitting pose at the hitting time with the
//! bat velocity, follow through, return home — one setpoint per cycle,
//! re-planned online whenever a refined plan arrives.
//!
//! The stroke is planned in the KR 6 R900's joint space, where the robot's
//! limits are: the hitting pose and the bat velocity become a joint target
//! (the inverse kinematics nearest the current joints, so the
//! configuration stays continuous, and the joint velocity that gives the
//! bat velocity), and Ruckig (`rsruckig`, the field-standard online
//! trajectory generator) moves all six axes, time-synchronised, within
//! [`JOINT_LIMIT_FRACTION`] of each axis's speed and acceleration (jerk:
//! full acceleration in [`JERK_RAMP_S`]). No stroke can ask an axis for
//! more than it has, pass a software limit switch on the way (the limits
//! are checked at the target, and along the path: a time-synchronised
//! profile may swing an axis well past its target to turn it round, so a
//! stroke whose path comes within [`PATH_LIMIT_MARGIN_RAD`] of a limit,
//! within [`PATH_WRIST_MARGIN`] of the singular wrist, or takes the TCP
//! out of the workspace's box or orientation range is refused), or sweep
//! through a singularity at speed. Each setpoint is the
//! forward kinematics of the sampled joints: a TCP pose in B, as RSI's
//! POSCORR wants it.
//!
//! The hitting time is met with Ruckig's `minimum_duration`: the
//! time-optimal profile is stretched to end exactly at the hit. If the hit
//! cannot be reached in time the profile ends as early as the limits
//! allow and the lateness is reported ([`StrokeGenerator::late_by`]); a
//! new ball's stroke later than [`MAX_LATE_S`] is refused while another
//! ball's stroke is under way (from rest it is taken: refinements blend
//! onto the moving arm). Re-planning
//! starts from the state the last setpoint was sampled from, so the joint
//! path stays continuous in velocity and acceleration across plan changes.
//!
//! A time-optimal stroke ends in limit-bound acceleration towards a
//! non-zero velocity, where Ruckig answers even a millimetre's refinement
//! by arriving late. So a stroke is first planned at [`HEADROOM_FRACTION`]
//! of the acceleration where it still arrives on time and its run-up stays
//! where a target may be (inside the box and the joint margins), and a
//! refinement that a new stroke would meet late is blended onto the
//! committed one ([`super::blend`]: a quintic correction per axis) where
//! the sum stays within the limits. A refinement for the same ball (the
//! same trajectory, or a hit within [`KEEP_MAX_DT_S`] of the old one) that
//! neither meets on time (a face turned late can ask tens of degrees of
//! the wrist) is taken in part: its hitting point, and the largest share of
//! its turn of the face that a new stroke meets on time. Only where no part
//! works does the old weighing apply, for a hit within [`KEEP_MAX_DT_S`]:
//! a late new stroke against keeping the old one; any other stroke later
//! than [`MAX_LATE_S`] is refused while another ball's is under way.
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
//! speed and orientation are clamped to the cell's limits; a hitting pose
//! with no joint solution within the software limits, at the singular
//! wrist, or whose bat velocity the axes cannot reach is refused or slowed
//! (the reason: [`PlanRejected::key`]). Follow-through and return run at
//! [`CALM_LIMIT_FRACTION`] of the joint limits.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use rsruckig::prelude::*;

use super::MotionLimits;
use super::blend::Blend;
use super::margins::{
    JERK_RAMP_S, JOINT_LIMIT_FRACTION, ORIENTATION_MARGIN_RAD, PATH_LIMIT_MARGIN_RAD, PATH_ORIENTATION_MARGIN_RAD,
    PATH_WALL_MARGIN_M, PATH_WRIST_MARGIN, VELOCITY_STEP_S, WRIST_MARGIN,
};
use super::reach;
use crate::geometry::{Pose6, unwrap_near};
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
/// Duration nudges tried when Ruckig misses the hitting time, s.
const RETRY_NUDGES_S: [f64; 4] = [-0.0003, 0.0003, -0.0007, 0.0007];
/// Share of the stroke's acceleration (and jerk) a plan is first tried
/// at, where it still arrives on time: a time-optimal stroke ends in
/// limit-bound acceleration, where a refinement can only arrive late; the
/// rest is room for blending refinements in ([`super::blend`]).
pub(crate) const HEADROOM_FRACTION: f64 = 0.7;
/// Instants between now and the hit at which the path of a stroke (with
/// headroom, at the full limits) or a blend is checked.
const PATH_CHECKS: usize = 16;
/// A blend's speeds and accelerations are checked this often, s (a
/// jerk ramp is 12.5 ms) …
const RATE_CHECK_S: f64 = 0.001;
/// … at most this many times (a blend over 0.25 s is checked coarser).
const MAX_RATE_CHECKS: usize = 256;
/// Halvings of the share of a late refinement's change of face and bat
/// velocity that is taken on time (the share is found to 1/16).
const PART_STEPS: usize = 4;
/// Share of the stroke's limits for follow-through and return.
pub(crate) const CALM_LIMIT_FRACTION: f64 = 0.5;
/// A stroke arriving later than this is refused while another ball's
/// stroke is under way, s (the bat would be ~4 cm behind a ball crossing
/// at 4 m/s), unless it refines a hit within [`KEEP_MAX_DT_S`] and is
/// weighed against the old stroke.
pub(crate) const MAX_LATE_S: f64 = 0.010;

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
    /// The hitting time is beyond `MAX_PLAN_HORIZON_S`.
    #[error("hit time too far ahead")]
    TooFarAhead,
    /// The hitting point is more than `MAX_OUTSIDE_M` outside the box.
    #[error("hitting point outside the workspace")]
    OutsideWorkspace,
    /// Ruckig found no trajectory (should not happen after sanitising).
    #[error("no trajectory to the hitting pose")]
    NoTrajectory,
    /// The hitting pose has no joint solution.
    #[error("hitting pose out of the arm's reach")]
    OutOfReach,
    /// The hitting pose breaks an axis limit (software limit switch, or
    /// the singular wrist).
    #[error("hitting pose breaks {0}")]
    Joint(LimitViolation),
    /// The stroke arrives too late, within the axes' limits.
    #[error("stroke would arrive too late")]
    TooLate,
    /// The stroke's path would come within `PATH_LIMIT_MARGIN_RAD` of a
    /// software limit switch or `PATH_WRIST_MARGIN` of the singular wrist,
    /// or take the TCP out of the workspace (its box or orientation range,
    /// where the safety filter brakes):
    /// Ruckig's fastest profile may swing an axis past its target to turn
    /// it round.
    #[error("stroke's path leaves the axes' range or the workspace")]
    PathOutside,
    /// The arm is not home and following (going home at commissioning
    /// speed, held, or stopped by the controller): no stroke is planned
    /// (`rsi::session`).
    #[error("the arm is not home and following")]
    NotHome,
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
            PlanRejected::PathOutside => "path_outside",
            PlanRejected::NotHome => "not_home",
        }
    }
}

/// The accepted target of a plan, in B.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct StrokeTarget {
    /// The `seq` of the plan this target came from.
    pub seq: u32,
    /// The ball's trajectory id, as the plan named it.
    pub trajectory: u32,
    /// When the TCP should be at `pose`, s on the `Instant` clock.
    pub hit_time: f64,
    /// TCP pose at the hit (m, rad), pulled into the workspace if needed.
    pub pose: Pose6,
    /// TCP velocity at the hit (m/s; rotational components are 0), speed
    /// clamped to the cell's bat-speed limit and to what the axes reach.
    pub velocity: Pose6,
    /// Whether the plan had to be clamped to fit the cell.
    pub clamped: bool,
    /// The joints at the hit, rad.
    pub joints: Joints,
    /// The joint velocity at the hit, rad/s.
    pub joint_velocity: [f64; AXES],
}

type Otg = Ruckig<6, IgnoreErrorHandler>;

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
    /// A refinement blended onto `traj` (approach only).
    blend: Option<Blend>,
    /// The last sampled joint state and its time.
    q: [f64; AXES],
    qd: [f64; AXES],
    qdd: [f64; AXES],
    t_last: f64,
    /// The TCP pose of `q` (angles unwrapped near the last) …
    p: Pose6,
    /// … computed at these joints (NaN: not the kinematics of any; an
    /// arm at rest keeps its pose without a forward kinematics a cycle).
    p_of: [f64; AXES],
    late_by: f64,
    /// Ruckig calculations done.
    pub calculations: u64,
    /// Ruckig calculations that failed.
    pub failures: u64,
    /// Refinements not taken because they would arrive late.
    pub kept: u64,
    /// Refinements blended onto the committed stroke.
    pub blended: u64,
    /// Late refinements taken in part (their hitting point, and as much of
    /// their change of face and bat velocity as a stroke meets on time).
    pub taken_in_part: u64,
}

fn secs(t: Instant) -> f64 {
    t.as_secs_f64()
}

impl StrokeGenerator {
    /// A generator at rest at `start`, at time `now`.
    pub fn new(lim: MotionLimits, now: Instant, start: Pose6) -> Self {
        let home_joints = lim.home_joints;
        let mut g = StrokeGenerator {
            otg: Ruckig::new(None, lim.dt),
            traj: Trajectory::new(None),
            spare: Trajectory::new(None),
            input: InputParameter::new(None),
            lim,
            t0: 0.0,
            phase: Phase::Hold,
            target: None,
            blend: None,
            q: home_joints.0,
            qd: [0.0; AXES],
            qdd: [0.0; AXES],
            t_last: 0.0,
            p: start,
            p_of: [f64::NAN; AXES],
            late_by: 0.0,
            calculations: 0,
            failures: 0,
            kept: 0,
            blended: 0,
            taken_in_part: 0,
        };
        g.set_limit_scale(1.0);
        g.reset(now, start);
        g
    }

    /// Restarts at rest at `start` (e.g. the robot's pose at RSI start) and
    /// returns home from there.
    pub fn reset(&mut self, now: Instant, start: Pose6) {
        let near = self.lim.home_joints;
        self.q = self.lim.arm.inverse_near(&Pose::from_pose6(&start), &near).unwrap_or(near).0;
        self.qd = [0.0; AXES];
        self.qdd = [0.0; AXES];
        self.p = start;
        self.p_of = [f64::NAN; AXES];
        self.t_last = secs(now);
        self.target = None;
        self.late_by = 0.0;
        self.go_home();
    }

    /// The box strokes keep to (position and orientation in B): the
    /// workspace, or less of it where the controller's correction limits
    /// end sooner (a start off home, `rsi::session`).
    pub fn set_box(&mut self, lo: Pose6, hi: Pose6) {
        self.lim.lo = lo;
        self.lim.hi = hi;
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

    /// The generator's floor for |A5| at a stroke's joints, rad.
    fn wrist(&self) -> f64 {
        WRIST_MARGIN * self.lim.arm.limits.singular_a5
    }

    /// The limits in use.
    pub fn limits(&self) -> &MotionLimits {
        &self.lim
    }

    /// The last setpoint: the TCP pose of [`Self::joints`] (B, m and rad).
    pub fn pose(&self) -> Pose6 {
        self.p
    }

    /// The joints of the last setpoint, rad.
    pub fn joints(&self) -> Joints {
        Joints(self.q)
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
            let (a, j) = (lim.amax[i], lim.jmax[i]);
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
            let x = abc[i].clamp(lim.lo[k] + ORIENTATION_MARGIN_RAD, lim.hi[k] - ORIENTATION_MARGIN_RAD);
            if x != abc[i] {
                clamped = true;
            }
            pose[k] = x;
        }
        let mut target = StrokeTarget {
            seq: plan.seq,
            trajectory: plan.trajectory,
            hit_time,
            pose,
            velocity: vel,
            clamped,
            joints: Joints(self.q),
            joint_velocity: [0.0; AXES],
        };
        self.to_joints(&mut target)?;
        Ok(target)
    }

    /// The joint target of a stroke: the hitting pose's joints nearest the
    /// current ones (within the software limits, off the singular wrist)
    /// and the joint velocity of the bat velocity, slowed where an axis
    /// would exceed its share of its speed.
    fn to_joints(&self, t: &mut StrokeTarget) -> Result<(), PlanRejected> {
        let arm = &self.lim.arm;
        let q = match arm.inverse_near(&Pose::from_pose6(&t.pose), &Joints(self.q)) {
            Ok(q) => q,
            Err(Unreachable::OutOfReach) => return Err(PlanRejected::OutOfReach),
            Err(Unreachable::Limit(v)) => return Err(PlanRejected::Joint(v)),
        };
        arm.limits.check_position(&q).map_err(PlanRejected::Joint)?;
        reach::inside_margin(&self.lim, &q).map_err(PlanRejected::Joint)?;
        reach::clear_of_singularities(&self.lim, &Joints(self.q), &q, self.wrist()).map_err(PlanRejected::Joint)?;
        let qd = reach::joint_velocity(&self.lim, &t.pose, &q, &t.velocity, VELOCITY_STEP_S);
        let share = reach::speed_share(&self.lim, &qd);
        let mut slow = if share > 1.0 { 1.0 / share } else { 1.0 };
        // After the hit the axes brake to rest: where they stop must be
        // clear too, else the bat goes slower.
        let mut attempt = 0;
        loop {
            let stop = reach::stop_point(&self.lim, &q, &qd.map(|x| x * slow));
            match reach::clear_to_rest(&self.lim, &Joints(self.q), &stop, self.wrist()) {
                Ok(()) => break,
                Err(v) if attempt == reach::REST_HALVINGS => return Err(PlanRejected::Joint(v)),
                Err(_) => {
                    slow *= 0.5;
                    attempt += 1;
                }
            }
        }
        if slow < 1.0 {
            for x in &mut t.velocity {
                *x *= slow;
            }
            t.clamped = true;
        }
        t.joints = q;
        t.joint_velocity = qd.map(|x| x * slow);
        Ok(())
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
        let target = self.target_of(plan)?;
        let duration = target.hit_time - self.t_last;
        // Keep the current stroke aside: a refinement that can no longer be
        // met on time by a new stroke may be blended onto it, and one that
        // cannot be blended either but differs only a little is not worth
        // arriving late.
        std::mem::swap(&mut self.traj, &mut self.spare);
        let (old_t0, old_target, old_phase, old_blend) = (self.t0, self.target, self.phase, self.blend);
        let restore = |g: &mut Self| {
            std::mem::swap(&mut g.traj, &mut g.spare);
            g.t0 = old_t0;
            g.blend = old_blend;
        };
        // A new or refined stroke with headroom, where it arrives on time.
        if self.calculate_with_headroom(&target, duration) {
            return Ok(self.take(target, 0.0));
        }
        // Late, for the same ball: blend the change onto the committed
        // stroke where the axes allow it, or take the largest share of it
        // that is on time. The same ball is the same trajectory, or one
        // whose hit comes within `KEEP_MAX_DT_S` (a track the estimator
        // lost and found again): a spin read anew moves the hit by more.
        let near_in_time = old_phase == Phase::Approach
            && old_target.is_some_and(|old| (old.hit_time - target.hit_time).abs() <= KEEP_MAX_DT_S);
        let same_ball = near_in_time
            || old_phase == Phase::Approach && old_target.is_some_and(|old| old.trajectory == target.trajectory);
        if same_ball && old_target.is_some_and(|old| old.hit_time > self.t_last) {
            restore(self);
            if self.blend_to(&target) {
                self.blended += 1;
                return Ok(self.take(target, 0.0));
            }
            std::mem::swap(&mut self.traj, &mut self.spare);
        }
        if !self.calculate_at_full_limits(&target.joints.0, &target.joint_velocity, duration) {
            restore(self);
            return Err(PlanRejected::NoTrajectory);
        }
        let late_by = (self.traj.get_duration() - duration).max(0.0);
        if late_by > LATE_TOLERANCE_S
            && same_ball
            && let Some(old) = old_target
            && old.hit_time > self.t_last
            && let Some(part) = self.on_time_part(&old, &target, duration)
        {
            self.taken_in_part += 1;
            return Ok(self.take(part, 0.0));
        }
        // Later than `MAX_LATE_S` only a refinement near the old hit in
        // time is worth it (weighed against the old stroke below).
        // From rest (holding, or on the way home) a late stroke is still
        // the ball's best chance: the next refinements blend onto the
        // moving arm, and a ball read faster than the first plans said
        // (topspin read low at first) is often met after all. Under way,
        // the stroke for the ball before is kept.
        if late_by > MAX_LATE_S && !near_in_time && old_phase == Phase::Approach {
            restore(self);
            return Err(PlanRejected::TooLate);
        }
        if !self.path_within_limits(self.traj.get_duration()) {
            restore(self);
            return Err(PlanRejected::PathOutside);
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
        Ok(self.take(target, late_by))
    }

    /// `target` is the stroke's now, arriving `late_by` late.
    fn take(&mut self, target: StrokeTarget, late_by: f64) -> &StrokeTarget {
        self.late_by = late_by;
        self.phase = Phase::Approach;
        self.target = Some(target);
        self.target.as_ref().expect("just set")
    }

    /// The stroke to `target` at [`HEADROOM_FRACTION`] of the stroke's
    /// acceleration and jerk, if that arrives on time: true, and it is the
    /// trajectory. Not tried where an axis already accelerates harder.
    fn calculate_with_headroom(&mut self, target: &StrokeTarget, duration: f64) -> bool {
        let l = &self.lim.arm.limits;
        let gentle = HEADROOM_FRACTION * JOINT_LIMIT_FRACTION;
        if (0..AXES).any(|i| self.qdd[i].abs() > l.acceleration[i] * gentle) {
            return false;
        }
        self.set_acceleration_scale(HEADROOM_FRACTION);
        let on_time = self.calculate(&target.joints.0, &target.joint_velocity, Some(duration))
            && self.traj.get_duration() - duration <= LATE_TOLERANCE_S;
        self.set_acceleration_scale(1.0);
        // A gentler stroke runs up from further back: only where a
        // stroke's target could be.
        on_time && self.path_clear(duration)
    }

    /// The stroke is [`Self::clear`] at [`PATH_CHECKS`] instants over the
    /// next `duration` s.
    fn path_clear(&self, duration: f64) -> bool {
        self.path_all(duration, |q| self.clear(q))
    }

    /// The stroke keeps the TCP in the workspace (box and orientation range,
    /// where the safety filter would brake it), the axes
    /// [`PATH_LIMIT_MARGIN_RAD`] inside their software limits and A5
    /// [`PATH_WRIST_MARGIN`] off the singular wrist on its side, at
    /// [`PATH_CHECKS`] instants over the next `duration` s.
    fn path_within_limits(&self, duration: f64) -> bool {
        let wrist = PATH_WRIST_MARGIN * self.lim.arm.limits.singular_a5;
        self.path_all(duration, |q| {
            let off_wrist = q[4] * self.q[4] > 0.0 && q[4].abs() >= wrist;
            let q = Joints(*q);
            off_wrist && self.in_workspace(&q) && reach::inside_by(&self.lim, &q, PATH_LIMIT_MARGIN_RAD).is_ok()
        })
    }

    /// The TCP at joints `q` is [`PATH_WALL_MARGIN_M`] inside the workspace
    /// box and [`PATH_ORIENTATION_MARGIN_RAD`] inside its orientation range,
    /// the limits the safety filter brakes at.
    fn in_workspace(&self, q: &Joints) -> bool {
        let p = self.lim.arm.tcp(q).to_pose6();
        (0..6).all(|i| {
            let (v, margin) = if i < 3 {
                (p[i], PATH_WALL_MARGIN_M)
            } else {
                (unwrap_near(p[i], self.lim.home[i]), PATH_ORIENTATION_MARGIN_RAD)
            };
            v >= self.lim.lo[i] + margin && v <= self.lim.hi[i] - margin
        })
    }

    fn path_all(&self, duration: f64, ok: impl Fn(&[f64; AXES]) -> bool) -> bool {
        (1..=PATH_CHECKS).all(|k| {
            let t = self.t_last + duration * k as f64 / PATH_CHECKS as f64;
            self.sample_base(t).is_some_and(|(q, _, _)| ok(&q))
        })
    }

    /// Joints `q` are where a stroke may pass: inside the software limits
    /// with [`LIMIT_MARGIN_RAD`], clear of the singularities on the side
    /// the axes are on, the TCP in the workspace as [`Self::in_workspace`]
    /// has it ([`PATH_WALL_MARGIN_M`] inside the box, inside the
    /// orientation range).
    fn clear(&self, q: &[f64; AXES]) -> bool {
        let q = Joints(*q);
        self.in_workspace(&q)
            && reach::inside_margin(&self.lim, &q).is_ok()
            && reach::clear_of_singularities(&self.lim, &Joints(self.q), &q, self.wrist()).is_ok()
    }

    /// Blends the change from the committed stroke's hitting state to
    /// `target`'s onto it ([`Blend`]), if stroke and blend together stay
    /// within [`JOINT_LIMIT_FRACTION`] of the axes' speed and acceleration
    /// (checked every [`RATE_CHECK_S`]) and [`Self::clear`] (at about
    /// [`PATH_CHECKS`] instants): true, and the blend is in place.
    fn blend_to(&mut self, target: &StrokeTarget) -> bool {
        let (t_now, t_hit) = (self.t_last, target.hit_time);
        let Some((base_q, base_qd, _)) = self.sample_base(t_hit) else { return false };
        let x1 = core::array::from_fn(|i| target.joints.0[i] - base_q[i]);
        let v1 = core::array::from_fn(|i| target.joint_velocity[i] - base_qd[i]);
        let now = self.blend.map_or([[0.0; AXES]; 3], |b| b.at(t_now));
        let Some(blend) = Blend::new(t_now, t_hit - t_now, &now, &x1, &v1) else { return false };
        let l = &self.lim.arm.limits;
        // Speeds and accelerations every RATE_CHECK_S (the stroke's own
        // acceleration turns within a jerk ramp), the path at PATH_CHECKS.
        let d = t_hit - t_now;
        let n = ((d / RATE_CHECK_S).ceil() as usize).clamp(PATH_CHECKS, MAX_RATE_CHECKS);
        for k in 1..=n {
            let t = t_now + d * k as f64 / n as f64;
            let (Some((q, qd, qdd)), b) = (self.sample_base(t), blend.at(t)) else { return false };
            let over = (0..AXES).any(|i| {
                (qd[i] + b[1][i]).abs() > l.speed[i] * JOINT_LIMIT_FRACTION
                    || (qdd[i] + b[2][i]).abs() > l.acceleration[i] * JOINT_LIMIT_FRACTION
            });
            if over || (k * PATH_CHECKS % n < PATH_CHECKS && !self.clear(&core::array::from_fn(|i| q[i] + b[0][i]))) {
                return false;
            }
        }
        self.blend = Some(blend);
        true
    }

    /// The part of a late refinement a new stroke still meets on time: its
    /// hitting point whole, and the largest share of its change of face and
    /// bat velocity (halving [`PART_STEPS`] times; none as the last
    /// resort). A face turned late can ask tens of degrees of the wrist
    /// axes, which the time left cannot give; the share it can give brings
    /// the face nearer. `None` (and the whole refinement's late stroke
    /// calculated again) if no part is on time and within the limits.
    fn on_time_part(&mut self, old: &StrokeTarget, new: &StrokeTarget, duration: f64) -> Option<StrokeTarget> {
        let (mut lo, mut hi) = (0.0, 1.0);
        let (mut best, mut last_on_time) = (None, false);
        let on_time = |g: &mut Self, share: f64| {
            let t = g.part_of(old, new, share)?;
            (g.calculate(&t.joints.0, &t.joint_velocity, Some(duration))
                && g.traj.get_duration() - duration <= LATE_TOLERANCE_S
                && g.path_within_limits(duration))
            .then_some(t)
        };
        for _ in 0..PART_STEPS {
            let share = 0.5 * (lo + hi);
            let part = on_time(self, share);
            last_on_time = part.is_some();
            match part {
                Some(t) => {
                    best = Some(t);
                    lo = share;
                }
                None => hi = share,
            }
        }
        if best.is_none() {
            best = on_time(self, 0.0);
            last_on_time = best.is_some();
        }
        // The trajectory calculated last must be the one taken: the part's,
        // or the whole refinement's late one as `set_plan` calculated it.
        if !last_on_time {
            match best {
                Some(t) => self.calculate(&t.joints.0, &t.joint_velocity, Some(duration)),
                None => self.calculate_at_full_limits(&new.joints.0, &new.joint_velocity, duration),
            };
        }
        best
    }

    /// The stroke to joints `pos` and joint velocity `vel` at the full
    /// limits, ending `duration` s from now where it can; false if Ruckig
    /// fails. Ruckig's time-synchronisation step sometimes finds no
    /// profile for exactly this duration (numerically, not physically) and
    /// returns the end of a later interval. Nudging the duration by a
    /// fraction of a millisecond finds a profile in nearly all those cases.
    fn calculate_at_full_limits(&mut self, pos: &[f64; AXES], vel: &[f64; AXES], duration: f64) -> bool {
        if !self.calculate(pos, vel, Some(duration)) {
            return false;
        }
        for nudge in RETRY_NUDGES_S {
            if self.traj.get_duration() - duration <= LATE_TOLERANCE_S {
                break;
            }
            self.calculate(pos, vel, Some(duration + nudge));
        }
        true
    }

    /// `new` with `share` of its change of orientation and velocity from
    /// `old` (its position whole), and its joints; `None` where that pose
    /// has none within the limits.
    fn part_of(&self, old: &StrokeTarget, new: &StrokeTarget, share: f64) -> Option<StrokeTarget> {
        let mut t = *new;
        for i in 3..6 {
            t.pose[i] = old.pose[i] + share * (unwrap_near(new.pose[i], old.pose[i]) - old.pose[i]);
        }
        for i in 0..6 {
            t.velocity[i] = old.velocity[i] + share * (new.velocity[i] - old.velocity[i]);
        }
        self.to_joints(&mut t).ok().map(|()| t)
    }

    /// Replaces the state the next plan starts from (after the safety
    /// filter changed a setpoint: pose, velocity and acceleration in B),
    /// and re-plans the current phase from it.
    pub(crate) fn override_state(&mut self, p: Pose6, v: Pose6, _a: Pose6) {
        let arm = &self.lim.arm;
        if let Ok(q) = arm.inverse_near(&Pose::from_pose6(&p), &Joints(self.q)) {
            let qd = reach::joint_velocity(&self.lim, &p, &q, &v, -self.lim.dt);
            self.q = q.0;
            self.qd = qd;
            self.qdd = [0.0; AXES];
            self.p = p;
            self.p_of = [f64::NAN; AXES];
        }
        match (self.phase, self.target) {
            (Phase::Approach, Some(t)) if t.hit_time > self.t_last => {
                if !self.calculate(&t.joints.0, &t.joint_velocity, Some(t.hit_time - self.t_last)) {
                    self.go_home();
                }
            }
            (Phase::FollowThrough, Some(_)) => {
                let rest = self.q;
                if !self.calculate_calm(&rest) {
                    self.go_home();
                }
            }
            _ => self.go_home(),
        }
    }

    /// The setpoint for time `t` (the time the robot will be there): the
    /// TCP pose of the sampled joints.
    pub fn next(&mut self, t: Instant) -> Pose6 {
        let t = secs(t);
        // Phase changes at the end of each segment (at most three chain).
        for _ in 0..3 {
            let end = match self.blend {
                Some(b) if self.phase == Phase::Approach => b.end(),
                _ => self.t0 + self.traj.get_duration(),
            };
            if t < end || self.phase == Phase::Hold {
                break;
            }
            self.sample_into_state(end);
            match self.phase {
                Phase::Approach => {
                    // Brake to rest at the stroke's limits (checked clear
                    // when the plan was taken).
                    let rest = reach::stop_point(&self.lim, &Joints(self.q), &self.qd).0;
                    if self.calculate(&rest, &[0.0; AXES], None) {
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
        self.update_pose();
        self.p
    }

    /// `p` from `q` (forward kinematics; angles unwrapped near the last).
    fn update_pose(&mut self) {
        if self.p_of == self.q {
            return; // at rest: the same joints, the same pose
        }
        self.p_of = self.q;
        let tcp = self.lim.arm.tcp(&Joints(self.q)).to_pose6();
        self.p[..3].copy_from_slice(&tcp[..3]);
        for i in 3..6 {
            self.p[i] = unwrap_near(tcp[i], self.p[i]);
        }
    }

    fn go_home(&mut self) {
        let home = self.lim.home_joints.0;
        if self.calculate_calm(&home) {
            self.phase = Phase::Return;
        } else {
            self.phase = Phase::Hold;
        }
        self.target = None;
    }

    /// To rest at `q` at [`CALM_LIMIT_FRACTION`] of the stroke's limits.
    fn calculate_calm(&mut self, q: &[f64; AXES]) -> bool {
        self.set_limit_scale(CALM_LIMIT_FRACTION);
        let ok = self.calculate(q, &[0.0; AXES], None);
        self.set_limit_scale(1.0);
        ok
    }

    /// Ruckig's acceleration and jerk: [`JOINT_LIMIT_FRACTION`] of the
    /// axes', times `s` (the speed limit as it is).
    fn set_acceleration_scale(&mut self, s: f64) {
        let l = &self.lim.arm.limits;
        for i in 0..AXES {
            let a = l.acceleration[i] * JOINT_LIMIT_FRACTION * s;
            self.input.max_acceleration[i] = a;
            self.input.max_jerk[i] = a / JERK_RAMP_S;
        }
    }

    /// Ruckig's limits: [`JOINT_LIMIT_FRACTION`] of the axes', times `s`.
    fn set_limit_scale(&mut self, s: f64) {
        let l = &self.lim.arm.limits;
        for i in 0..AXES {
            self.input.max_velocity[i] = l.speed[i] * JOINT_LIMIT_FRACTION * s;
        }
        self.set_acceleration_scale(s);
    }

    /// Samples the trajectory at absolute time `t` into the joint state. An
    /// empty trajectory (every axis at rest at its target) leaves the
    /// joints as they are: Ruckig samples its disabled axes as zeros.
    fn sample_into_state(&mut self, t: f64) {
        let Some((q, qd, qdd)) = self.sample_base(t) else {
            self.qd = [0.0; AXES];
            self.qdd = [0.0; AXES];
            self.t_last = t;
            return;
        };
        let b = self.blend.map_or([[0.0; AXES]; 3], |b| b.at(t));
        for i in 0..AXES {
            self.q[i] = q[i] + b[0][i];
            self.qd[i] = qd[i] + b[1][i];
            self.qdd[i] = qdd[i] + b[2][i];
        }
        self.t_last = t;
    }

    /// `traj` (without the blend) at absolute time `t`: joints, speeds,
    /// accelerations; `None` for an empty trajectory.
    fn sample_base(&self, t: f64) -> Option<([f64; AXES], [f64; AXES], [f64; AXES])> {
        if self.traj.get_duration() <= 0.0 {
            return None;
        }
        let mut p = DataArrayOrVec::Stack([0.0; 6]);
        let mut v = DataArrayOrVec::Stack([0.0; 6]);
        let mut a = DataArrayOrVec::Stack([0.0; 6]);
        let mut section = None;
        let dt = (t - self.t0).max(0.0);
        self.traj.at_time(dt, &mut Some(&mut p), &mut Some(&mut v), &mut Some(&mut a), &mut None, &mut section);
        Some((core::array::from_fn(|i| p[i]), core::array::from_fn(|i| v[i]), core::array::from_fn(|i| a[i])))
    }

    /// A new joint trajectory from the state at `t_last` to `pos` with
    /// velocity `vel`; false (and the old trajectory kept) if Ruckig fails.
    fn calculate(&mut self, pos: &[f64; AXES], vel: &[f64; AXES], min_duration: Option<f64>) -> bool {
        self.blend = None;
        for i in 0..AXES {
            self.input.current_position[i] = self.q[i];
            self.input.current_velocity[i] = self.qd[i];
            self.input.current_acceleration[i] = self.qdd[i];
            self.input.target_position[i] = pos[i];
            self.input.target_velocity[i] = vel[i];
            self.input.target_acceleration[i] = 0.0;
            // An axis already resting at its target is left out: Ruckig's
            // time synchronisation can fail on such (numerically) empty
            // moves and return a later duration for all axes.
            let resting = (pos[i] - self.q[i]).abs() < 1e-7
                && self.qd[i].abs() < 1e-7
                && self.qdd[i].abs() < 1e-6
                && vel[i] == 0.0;
            self.input.enabled[i] = !resting;
            if resting {
                self.input.current_position[i] = pos[i];
                self.input.current_velocity[i] = 0.0;
                self.input.current_acceleration[i] = 0.0;
            }
        }
        self.input.minimum_duration = min_duration;
        self.calculations += 1;
        // What Ruckig would refuse is refused here: its refusal formats a
        // message (an allocation on the RSI thread). A target speed over
        // the limit by rounding is brought onto it.
        let mut valid = true;
        for i in 0..AXES {
            let (pf, vf, v_max) =
                (self.input.target_position[i], self.input.target_velocity[i], self.input.max_velocity[i]);
            if !(pf.is_finite() && vf.is_finite() && self.input.current_position[i].is_finite()) {
                valid = false;
            } else if vf.abs() > v_max {
                if vf.abs() > v_max * (1.0 + 1e-6) {
                    valid = false;
                }
                self.input.target_velocity[i] = vf.clamp(-v_max, v_max);
            }
        }
        let ok = valid && matches!(self.otg.calculate(&self.input, &mut self.traj), Ok(RuckigResult::Working));
        if ok {
            self.t0 = self.t_last;
        } else {
            self.failures += 1;
            // Brake within the limits and come back to where we are; only
            // where even that cannot be planned, hold still (a trajectory
            // of zero length: from speed, a step the axes cannot follow).
            for i in 0..AXES {
                self.input.current_position[i] = self.q[i];
                self.input.current_velocity[i] = self.qd[i];
                self.input.current_acceleration[i] = self.qdd[i];
                self.input.target_position[i] = self.q[i];
                self.input.target_velocity[i] = 0.0;
                self.input.target_acceleration[i] = 0.0;
                self.input.enabled[i] = true;
            }
            self.input.minimum_duration = None;
            let moving = (0..AXES).any(|i| self.qd[i] != 0.0 || self.qdd[i] != 0.0);
            let braking = moving
                && (0..AXES).all(|i| self.q[i].is_finite() && self.qd[i].is_finite() && self.qdd[i].is_finite())
                && matches!(self.otg.calculate(&self.input, &mut self.traj), Ok(RuckigResult::Working));
            if !braking {
                for i in 0..AXES {
                    self.input.current_velocity[i] = 0.0;
                    self.input.current_acceleration[i] = 0.0;
                }
                let _ = self.otg.calculate(&self.input, &mut self.traj);
            }
            self.t0 = self.t_last;
        }
        ok
    }
}

#[cfg(test)]
#[path = "generator_tests.rs"]
mod tests;
