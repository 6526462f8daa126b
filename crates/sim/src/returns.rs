//! Judging returns, not touches: where the bat's actual path
//! (the mock KR C4's `RIst` log) first meets the true ball, what the rubber
//! does to it there ([`RacketModel`]), and where the ball then flies with
//! the simulator's own physics — over the net onto the opponent's half, or
//! why not.
//!
//! The bat is a disc of the rubber's `bat_radius` about the TCP, its
//! hitting face looking along [`EulerZyx::face_normal`] (−x of the TCP
//! frame). The actual pose is logged every 4 ms cycle: between samples the
//! centre is interpolated linearly and the orientation along the shortest
//! rotation; the velocity and angular velocity are central differences at
//! the samples, interpolated the same way. The contact is the first moment
//! within ±[`STROKE_WINDOW`] of the true crossing of the hitting plane at
//! which the ball, coming from in front of the face, touches its plane
//! (its centre one radius away) inside the disc.
//!
//! A failed return says why: for a contact, the run of face tilts that
//! would have returned the ball with the same heading and bat velocity
//! (the bat's angle), or that none would (its speed); without one, how far
//! from the bat the ball crossed the face's plane (position), or that the
//! face never reached the ball's path (timing).
//!
//! Owns the judgement only: no clock, no I/O; the demo and the virtual cell
//! call it (`demo::judge_strokes`).

use nalgebra::{Rotation3, UnitQuaternion};
use serde::Serialize;

use crate::launcher::Launch;
use crate::mock_krc::PathSample;
use crate::truth::Flight;
use topspin_core::calib::Calibration;
use topspin_core::calib::RobotFile;
use topspin_core::estimator::face_normal;
use topspin_core::geometry::EulerZyx;
use topspin_core::physics::{BallState, Bat, Event, Impact, Propagator, RacketModel, Regime, StopAt, Vec3};
use topspin_core::plan::face_tilt;
use topspin_core::time::{Duration, Instant};

/// How far from the true crossing of the hitting plane the bat may meet
/// the ball: 50 ms is 0.2–0.4 m of the ball's flight either side, more
/// than the workspace holds along x.
pub const STROKE_WINDOW: Duration = Duration::from_millis(50);

/// Longest flight of a return that is followed, s.
const RETURN_T_MAX: f64 = 3.0;

/// Why a reachable ball did not come back onto the opponent's half.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ReturnFail {
    /// The bat's face never met the ball (timing or position).
    NoContact,
    /// The return touched the net.
    Net,
    /// It came down on the robot's side of the net (or flew backwards).
    Short,
    /// It passed the opponent's end of the table.
    Long,
    /// It passed beside the table.
    Wide,
}

impl ReturnFail {
    /// Every reason, in report order.
    pub const ALL: [ReturnFail; 5] =
        [ReturnFail::NoContact, ReturnFail::Net, ReturnFail::Short, ReturnFail::Long, ReturnFail::Wide];

    /// The name in the JSON.
    pub fn name(self) -> &'static str {
        match self {
            ReturnFail::NoContact => "no_contact",
            ReturnFail::Net => "net",
            ReturnFail::Short => "short",
            ReturnFail::Long => "long",
            ReturnFail::Wide => "wide",
        }
    }
}

/// The bat and the ball at their contact.
#[derive(Copy, Clone, Debug, Serialize)]
pub struct ContactReport {
    /// Contact time against the ball's true crossing of the hitting plane,
    /// ms (< 0: before it).
    pub dt_ms: f64,
    /// Where the ball touched the face, from its centre, mm.
    pub offset_mm: f64,
    /// The bat centre's speed, m/s.
    pub bat_speed_mps: f64,
    /// Bat speed along the face's normal (towards the ball), m/s.
    pub bat_normal_speed_mps: f64,
    /// The face's tilt: elevation of its normal, degrees (> 0 open).
    pub face_tilt_deg: f64,
    /// The face normal's heading in the table plane, degrees from −x
    /// towards +y.
    pub face_yaw_deg: f64,
    /// For a failed return: the face tilts (whole degrees, the run nearest
    /// the actual one) that would have returned it with the same heading
    /// and bat velocity.
    pub returning_tilt_deg: Option<[f64; 2]>,
    /// The ball's speed just before and just after the contact, m/s.
    pub ball_in_mps: f64,
    /// The ball's speed just after the contact, m/s.
    pub ball_out_mps: f64,
    /// The ball's spin just after the contact, rps.
    pub spin_out_rps: [f64; 3],
    /// How the rubber held the ball.
    pub regime: Regime,
    /// The multiples of the ball's true spin at the contact (on a grid
    /// from ×0.5 to ×2) over which the same bat there returns it
    /// ([`spin_window`]): the stroke's tolerance to the spin's size.
    pub spin_window: Option<[f64; 2]>,
}

/// The verdict on one ball's return.
#[derive(Clone, Debug)]
pub struct ReturnJudgement {
    /// `None`: over the net onto the opponent's half.
    pub fail: Option<ReturnFail>,
    /// The bat and the ball at their contact (`None`: no contact).
    pub contact: Option<ContactReport>,
    /// Where the return first came down to the table's height (x, y), m.
    pub landing: Option<[f64; 2]>,
    /// The ball just after the contact, and when (s after launch).
    pub after: Option<(f64, BallState)>,
    /// Why it failed: bat angle, speed, timing or position.
    pub why: Option<String>,
}

impl ReturnJudgement {
    /// No contact, and why.
    fn no_contact(why: String) -> Self {
        ReturnJudgement { fail: Some(ReturnFail::NoContact), contact: None, landing: None, after: None, why: Some(why) }
    }

    /// True when the ball went back over the net onto the opponent's half.
    pub fn returned(&self) -> bool {
        self.fail.is_none()
    }
}

/// The actual bat path in the table frame.
#[derive(Clone, Debug)]
pub struct BatPath {
    t: Vec<Instant>,
    centre: Vec<Vec3>,
    rot: Vec<UnitQuaternion<f64>>,
}

impl BatPath {
    /// The logged path (`actual`: mm and KUKA A/B/C degrees in B) in T.
    pub fn new(robot: &RobotFile, path: &[PathSample]) -> Self {
        let yaw = Rotation3::from_axis_angle(&Vec3::z_axis(), robot.base_yaw());
        let mut out = BatPath {
            t: Vec::with_capacity(path.len()),
            centre: Vec::with_capacity(path.len()),
            rot: Vec::with_capacity(path.len()),
        };
        for s in path {
            let a = s.actual;
            let r_b = EulerZyx { a: a[3].to_radians(), b: a[4].to_radians(), c: a[5].to_radians() }.matrix();
            let r_t = yaw * Rotation3::from_matrix_unchecked(r_b);
            out.t.push(s.t);
            out.centre.push(robot.b_to_t(Vec3::new(a[0], a[1], a[2]) * 1e-3));
            out.rot.push(UnitQuaternion::from_rotation_matrix(&r_t));
        }
        out
    }

    /// A path from poses in T directly (tests, other logs): times, centres
    /// and orientations as Euler ZYX in T.
    pub fn from_poses(t: &[Instant], centre: &[Vec3], orientation: &[EulerZyx]) -> Self {
        let rot = orientation
            .iter()
            .map(|o| UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(o.matrix())))
            .collect();
        BatPath { t: t.to_vec(), centre: centre.to_vec(), rot }
    }

    /// Velocity and angular velocity at sample `i` (central differences,
    /// one-sided at the ends).
    fn rates(&self, i: usize) -> (Vec3, Vec3) {
        let (lo, hi) = (i.saturating_sub(1), (i + 1).min(self.t.len() - 1));
        let dt = self.t[hi].secs_since(self.t[lo]);
        if dt <= 0.0 || dt.is_nan() {
            return (Vec3::zeros(), Vec3::zeros());
        }
        let v = (self.centre[hi] - self.centre[lo]) / dt;
        let w = (self.rot[hi] * self.rot[lo].inverse()).scaled_axis() / dt;
        (v, w)
    }

    /// The bat at `t`, or `None` outside the logged span.
    pub fn at(&self, t: Instant) -> Option<Bat> {
        let n = self.t.len();
        if n < 2 || t < self.t[0] || t > self.t[n - 1] {
            return None;
        }
        let i = self.t.partition_point(|s| *s <= t).clamp(1, n - 1) - 1;
        let span = self.t[i + 1].secs_since(self.t[i]);
        let u = if span > 0.0 { (t.secs_since(self.t[i]) / span).clamp(0.0, 1.0) } else { 0.0 };
        let centre = self.centre[i].lerp(&self.centre[i + 1], u);
        let rot = self.rot[i].slerp(&self.rot[i + 1], u);
        let (v0, w0) = self.rates(i);
        let (v1, w1) = self.rates(i + 1);
        Some(Bat { centre, normal: -(rot * Vec3::x()), vel: v0.lerp(&v1, u), omega: w0.lerp(&w1, u) })
    }
}

/// Where the ball meets the face, if it does.
#[derive(Copy, Clone, Debug)]
struct Touch {
    /// s after launch.
    t: f64,
    ball: BallState,
    bat: Bat,
    offset: f64,
}

/// Signed gap between the ball's surface and the face's plane, m.
fn gap(ball: &BallState, bat: &Bat, r: f64) -> f64 {
    (ball.pos - bat.centre).dot(&bat.normal) - r
}

/// The first contact of the ball (launched at `start`) with the face within
/// the window around `t_hit` (s after launch); without one, how near the
/// ball's centre passed the disc's centre where it crossed the face's plane
/// (m; `None`: it never did).
fn find_touch(
    flight: &Flight<'_>,
    start: Instant,
    t_hit: f64,
    bat: &BatPath,
    r: f64,
    bat_radius: f64,
) -> Result<Touch, Option<f64>> {
    let w = STROKE_WINDOW.as_secs_f64();
    let at = |t: f64| start + Duration::from_nanos((t.max(0.0) * 1e9).round() as u64);
    let (t_lo, t_hi) = ((t_hit - w).max(0.0), t_hit + w);
    // The samples within the window, and the window's ends.
    let first = bat.t.partition_point(|s| *s < at(t_lo));
    let last = bat.t.partition_point(|s| *s <= at(t_hi));
    let mut times: Vec<f64> = Vec::with_capacity(last.saturating_sub(first) + 2);
    times.push(t_lo);
    times.extend(bat.t[first..last].iter().map(|s| s.secs_since(start)));
    times.push(t_hi);
    let mut walker = *flight;
    let mut prev: Option<(f64, f64, Flight<'_>)> = None;
    let mut nearest: Option<f64> = None;
    for &t in &times {
        let ball = walker.at(t);
        let Some(b) = bat.at(at(t)) else {
            prev = None;
            continue;
        };
        let g = gap(&ball, &b, r);
        if let Some((t0, g0, f0)) = prev
            && g0 > 0.0
            && g <= 0.0
        {
            // Bisect for the touch between t0 and t (the ball's state from
            // its own walker, through any bounce).
            let (mut lo, mut hi) = (t0, t);
            for _ in 0..50 {
                let mid = 0.5 * (lo + hi);
                let (mut f, Some(bm)) = (f0, bat.at(at(mid))) else { break };
                if gap(&f.at(mid), &bm, r) > 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
                if hi - lo < 1e-7 {
                    break;
                }
            }
            let mut f = f0;
            let ball = f.at(hi);
            if let Some(b) = bat.at(at(hi)) {
                let d = ball.pos - b.centre;
                let offset = (d - b.normal * d.dot(&b.normal)).norm();
                if offset <= bat_radius {
                    return Ok(Touch { t: hi, ball, bat: b, offset });
                }
                nearest = Some(nearest.map_or(offset, |n: f64| n.min(offset)));
            }
        }
        prev = Some((t, g, walker));
    }
    Err(nearest)
}

/// Where a return flies from `state` at `t`: over the net onto the
/// opponent's half (`None`) or why not, and where it came down to the
/// table's height.
pub fn fly_return(prop: &Propagator, state: &BallState, t: f64) -> (Option<ReturnFail>, Option<[f64; 2]>) {
    let table = prop.table;
    let r = prop.flight.radius();
    let (mut s, mut now) = (*state, t);
    let stop = StopAt { t_max: t + RETURN_T_MAX, hit_plane_x: None, net: true };
    match prop.advance(&mut s, &mut now, &stop) {
        Event::Net { .. } => (Some(ReturnFail::Net), None),
        Event::Bounce { before, .. } => {
            let xy = [before.pos.x, before.pos.y];
            (if before.pos.x < 0.0 { None } else { Some(ReturnFail::Short) }, Some(xy))
        }
        Event::Floor { .. } | Event::TimeLimit { .. } | Event::HitPlane { .. } => {
            // Off the table: where did it pass the table's height?
            let total = now - t;
            let (mut lo, mut hi) = (0.0, total);
            let above = |tau: f64| prop.fly(state, tau).pos.z - r > 0.0;
            if !above(0.0) || above(total) {
                return (Some(ReturnFail::Short), None);
            }
            for _ in 0..50 {
                let mid = 0.5 * (lo + hi);
                if above(mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let p = prop.fly(state, hi).pos;
            let fail = if p.x > 0.0 {
                ReturnFail::Short
            } else if p.y.abs() > table.width / 2.0 {
                ReturnFail::Wide
            } else {
                ReturnFail::Long
            };
            (Some(fail), Some([p.x, p.y]))
        }
    }
}

/// The face tilts, in whole degrees from −60° to 60° with the heading and
/// the bat's velocity as they were, that would have returned `ball` (the
/// state at contact, `t` s after launch): the run of them nearest the
/// actual tilt, or `None`.
fn returning_tilts(prop: &Propagator, racket: &RacketModel, ball: &BallState, bat: &Bat, t: f64) -> Option<[f64; 2]> {
    let n = bat.normal;
    let heading = (-n.y).atan2(-n.x);
    let actual = face_tilt(&n).to_degrees();
    let returns = |deg: i32| {
        let n = face_normal((deg as f64).to_radians(), heading);
        let v_s = bat.surface_velocity(&(ball.pos - n * racket.radius));
        racket.hit(ball, &n, &v_s).is_some_and(|i| fly_return(prop, &i.after, t).0.is_none())
    };
    let tilts: Vec<(f64, bool)> = (-60..=60).map(|deg| (deg as f64, returns(deg))).collect();
    nearest_run(&tilts, actual)
}

/// Steps of the spin window's grid per doubling of the spin (either way
/// from the ball's own, one doubling).
const SPIN_STEPS_PER_DOUBLING: i32 = 10;

/// The stroke's spin window: the run of multiples 2^(k/10), k in −10..=10
/// ([`SPIN_STEPS_PER_DOUBLING`]), of `ball`'s spin (the state at the
/// contact, `t` s after launch) with which the same `bat` returns it,
/// nearest ×1 — its ends are how much less and more spin the stroke
/// forgives. The ball's position and
/// velocity at the contact are held (the spin's effect on the arrival is
/// the timing window's); `None`: no multiple returns it.
pub fn spin_window(prop: &Propagator, racket: &RacketModel, ball: &BallState, bat: &Bat, t: f64) -> Option<[f64; 2]> {
    let n = bat.normal;
    let v_s = bat.surface_velocity(&(ball.pos - n * racket.radius));
    let multiple = |k: f64| 2f64.powf(k / f64::from(SPIN_STEPS_PER_DOUBLING));
    let returns = |k: f64| {
        let scaled = BallState { spin: ball.spin * multiple(k), ..*ball };
        racket.hit(&scaled, &n, &v_s).is_some_and(|i| fly_return(prop, &i.after, t).0.is_none())
    };
    let steps: Vec<(f64, bool)> =
        (-SPIN_STEPS_PER_DOUBLING..=SPIN_STEPS_PER_DOUBLING).map(f64::from).map(|k| (k, returns(k))).collect();
    nearest_run(&steps, 0.0).map(|r| r.map(multiple))
}

/// How far the ball's arrival is shifted at most when a stroke's timing
/// window is measured, ms (either way).
pub const TIMING_SPAN_MS: i64 = 30;

/// The stroke's timing window: the run of whole-millisecond shifts of the
/// ball's arrival (ms, > 0: the ball later, as if the bat were early)
/// within ±[`TIMING_SPAN_MS`] over which the same bat path still returns
/// the ball — the run nearest no shift (so it holds 0 for a returned
/// ball, and its ends are the stroke's tolerance either way). `None`: no
/// shift returns it.
pub fn timing_window(
    cal: &Calibration,
    prop: &Propagator,
    launch: &Launch,
    start: Instant,
    t_hit: f64,
    path: &BatPath,
) -> Option<[f64; 2]> {
    let racket = cal.racket_model();
    let returns = |shift_ms: i64| {
        let shifted = Instant(start.0.saturating_add_signed(shift_ms * 1_000_000));
        return_fail(&racket, prop, launch, shifted, t_hit, path).is_ok_and(|f| f.is_none())
    };
    let shifts: Vec<(f64, bool)> = (-TIMING_SPAN_MS..=TIMING_SPAN_MS).map(|k| (k as f64, returns(k))).collect();
    nearest_run(&shifts, 0.0)
}

/// Of the runs of consecutive `true` values in `points` (ascending by
/// their first), the one nearest `at`, as its first and last value.
fn nearest_run(points: &[(f64, bool)], at: f64) -> Option<[f64; 2]> {
    let mut best: Option<[f64; 2]> = None;
    let mut k = 0;
    while k < points.len() {
        if !points[k].1 {
            k += 1;
            continue;
        }
        let first = k;
        while k < points.len() && points[k].1 {
            k += 1;
        }
        let run = [points[first].0, points[k - 1].0];
        let dist = |r: &[f64; 2]| (r[0] - at).max(at - r[1]).max(0.0);
        if best.is_none_or(|b| dist(&run) < dist(&b)) {
            best = Some(run);
        }
    }
    best
}

/// The touch and where its return goes, without the reasons: `Err` when
/// the face never met the ball, `Ok(None)` when it was returned.
fn return_fail(
    racket: &RacketModel,
    prop: &Propagator,
    launch: &Launch,
    start: Instant,
    t_hit: f64,
    path: &BatPath,
) -> Result<Option<ReturnFail>, NoContact> {
    let (touch, impact) = contact(racket, prop, launch, start, t_hit, path)?;
    Ok(fly_return(prop, &impact.after, touch.t).0)
}

/// Why the bat gave the ball nothing.
enum NoContact {
    /// The face never met it: how near the ball's centre passed the
    /// disc's where it crossed the face's plane (m; `None`: it never did).
    Missed(Option<f64>),
    /// The face met it running away from it.
    RunningAway,
}

/// Where the face first meets the ball (`launch` at `start`, near its
/// crossing `t_hit` s after launch) and what the rubber does to it.
fn contact(
    racket: &RacketModel,
    prop: &Propagator,
    launch: &Launch,
    start: Instant,
    t_hit: f64,
    path: &BatPath,
) -> Result<(Touch, Impact), NoContact> {
    let flight = Flight::new(launch, prop);
    let touch =
        find_touch(&flight, start, t_hit, path, racket.radius, racket.params.bat_radius).map_err(NoContact::Missed)?;
    let impact = racket.hit_bat(&touch.ball, &touch.bat).ok_or(NoContact::RunningAway)?;
    Ok((touch, impact))
}

/// Judges the return of one ball: `launch` at `start` flying the physics
/// `prop` (in and out), its true crossing of the hitting plane `t_hit` s
/// after launch, the bat's actual `path`.
pub fn judge_return(
    cal: &Calibration,
    prop: &Propagator,
    launch: &Launch,
    start: Instant,
    t_hit: f64,
    path: &BatPath,
) -> ReturnJudgement {
    let racket = cal.racket_model();
    let (touch, impact) = match contact(&racket, prop, launch, start, t_hit, path) {
        Ok(c) => c,
        Err(NoContact::Missed(Some(m))) => {
            return ReturnJudgement::no_contact(format!(
                "position: the ball crossed the face's plane {:.0} mm from the bat's centre ({:.0} mm beyond its edge)",
                m * 1e3,
                (m - racket.params.bat_radius) * 1e3
            ));
        }
        Err(NoContact::Missed(None)) => {
            return ReturnJudgement::no_contact(format!(
                "timing: the face never reached the ball's path within ±{} ms of the hit",
                STROKE_WINDOW.0 / 1_000_000
            ));
        }
        Err(NoContact::RunningAway) => {
            return ReturnJudgement::no_contact("speed: the bat was running away from the ball".to_owned());
        }
    };
    let after = impact.after;
    let (fail, landing) = fly_return(prop, &after, touch.t);
    let bat = &touch.bat;
    let n = bat.normal;
    let tilt = face_tilt(&n).to_degrees();
    let returning = fail.map(|_| returning_tilts(prop, &racket, &touch.ball, bat, touch.t));
    let why = returning.map(|r| match r {
        Some([lo, hi]) if tilt < lo => {
            format!("angle: face {tilt:+.1}°, {:.1}° too closed ({lo:+.0}…{hi:+.0}° return it)", lo - tilt)
        }
        Some([lo, hi]) if tilt > hi => {
            format!("angle: face {tilt:+.1}°, {:.1}° too open ({lo:+.0}…{hi:+.0}° return it)", tilt - hi)
        }
        Some([lo, hi]) => format!(
            "angle at the edge: face {tilt:+.1}° within the {lo:+.0}…{hi:+.0}° that return it (by whole degrees)"
        ),
        None => format!("speed: no face angle returns it at this bat velocity ({:.2} m/s)", bat.vel.norm()),
    });
    let contact = ContactReport {
        dt_ms: (touch.t - t_hit) * 1e3,
        offset_mm: touch.offset * 1e3,
        bat_speed_mps: bat.vel.norm(),
        bat_normal_speed_mps: bat.vel.dot(&n),
        face_tilt_deg: tilt,
        face_yaw_deg: n.y.atan2(-n.x).to_degrees(),
        returning_tilt_deg: returning.flatten(),
        ball_in_mps: touch.ball.vel.norm(),
        ball_out_mps: after.vel.norm(),
        spin_out_rps: after.spin.map(topspin_core::physics::rad_to_rps).into(),
        regime: impact.regime,
        spin_window: spin_window(prop, &racket, &touch.ball, bat, touch.t),
    };
    ReturnJudgement { fail, contact: Some(contact), landing, after: Some((touch.t, after)), why }
}

/// Counts of failed returns by reason.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ReturnFails {
    /// The bat's face never met the ball.
    pub no_contact: usize,
    /// Returns that touched the net.
    pub net: usize,
    /// Returns that came down on the robot's side of the net (or flew backwards).
    pub short: usize,
    /// Returns that passed the opponent's end of the table.
    pub long: usize,
    /// Returns that passed beside the table.
    pub wide: usize,
}

impl ReturnFails {
    /// Adds one failure.
    pub fn add(&mut self, fail: ReturnFail) {
        match fail {
            ReturnFail::NoContact => self.no_contact += 1,
            ReturnFail::Net => self.net += 1,
            ReturnFail::Short => self.short += 1,
            ReturnFail::Long => self.long += 1,
            ReturnFail::Wide => self.wide += 1,
        }
    }

    /// The count for `fail`.
    pub fn get(&self, fail: ReturnFail) -> usize {
        match fail {
            ReturnFail::NoContact => self.no_contact,
            ReturnFail::Net => self.net,
            ReturnFail::Short => self.short,
            ReturnFail::Long => self.long,
            ReturnFail::Wide => self.wide,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::launcher::{Power, Setting, SpinType};
    use crate::{TrackerModel, simulate_ball};
    use topspin_core::estimator::paper_beta;
    use topspin_core::estimator::{AimBounds, aim, bat_velocity};

    /// The ball's launch instant in these tests.
    const START: Instant = Instant(1_000_000_000);

    /// A medium topspin ball, its true state at the hitting plane and the
    /// time (s after launch).
    fn ball(cal: &Calibration) -> (Launch, BallState, f64) {
        let setting = Setting::new(SpinType::Topspin, Power::Medium);
        let b = simulate_ball(3, 7, setting, &cal.propagator(), cal.strike.hit_plane_x, &TrackerModel::default())
            .expect("the launcher aims it");
        let h = b.truth.hit.expect("it reaches the plane");
        (b.truth.to_launch(), BallState::new(h.pos.into(), h.vel.into(), h.spin.into()), h.t)
    }

    /// A bat logged every 4 ms over ±0.1 s of `t_hit`, at `centre(t)` (t
    /// from the hit, s) with the face `o`.
    fn path(t_hit: f64, o: EulerZyx, centre: impl Fn(f64) -> Vec3) -> BatPath {
        let ts: Vec<f64> = (-25..=25).map(|k| k as f64 * 0.004).collect();
        let at = |dt: f64| START + Duration::from_nanos(((t_hit + dt) * 1e9).round() as u64);
        let t: Vec<Instant> = ts.iter().map(|&dt| at(dt)).collect();
        let c: Vec<Vec3> = ts.iter().map(|&dt| centre(dt)).collect();
        BatPath::from_poses(&t, &c, &vec![o; ts.len()])
    }

    /// The face and bat velocity the aim picks for the true ball.
    fn aimed(cal: &Calibration, s: &BallState) -> (EulerZyx, Vec3) {
        let a = aim(
            &AimBounds::of(&cal.strike),
            cal.strike.aim_target,
            &cal.propagator(),
            &cal.racket_model(),
            s,
            0.0,
            -paper_beta(&cal.strike, &s.spin),
            None,
            64,
        );
        assert!(a.converged, "{a:?}");
        (EulerZyx { a: a.heading, b: a.tilt, c: 0.0 }, bat_velocity(a.tilt, a.heading, a.speed))
    }

    #[test]
    fn the_path_is_interpolated_with_its_velocity() {
        let o = EulerZyx { a: 0.1, b: -0.3, c: 0.2 };
        let v = Vec3::new(-1.0, 0.2, 0.5);
        let p = path(0.5, o, |dt| Vec3::new(1.6, 0.0, 0.3) + v * dt);
        let b = p.at(START + Duration::from_nanos(500_001_000)).unwrap();
        assert!((b.vel - v).norm() < 1e-9, "{}", b.vel);
        assert!(b.omega.norm() < 1e-9);
        assert!((b.normal - o.face_normal()).norm() < 1e-9);
        assert!((b.centre - Vec3::new(1.6, 0.0, 0.3) - v * 1e-6).norm() < 1e-9);
        assert!(p.at(START).is_none(), "before the log");
    }

    #[test]
    fn a_bat_that_meets_the_ball_returns_it() {
        let cal = Calibration::default_cell();
        let (launch, s, t_hit) = ball(&cal);
        let (o, v) = aimed(&cal, &s);
        let p = path(t_hit, o, |dt| s.pos + v * dt);
        let j = judge_return(&cal, &cal.propagator(), &launch, START, t_hit, &p);
        assert!(j.returned(), "{j:?}");
        let c = j.contact.expect("a contact");
        // The face meets the ball's surface before its centre reaches the plan.
        assert!((-8.0..0.0).contains(&c.dt_ms) && c.offset_mm < 30.0, "{c:?}");
        assert!((c.bat_speed_mps - v.norm()).abs() < 1e-6 && (c.face_tilt_deg - o.b.to_degrees()).abs() < 1e-6);
        let [x, y] = j.landing.expect("it lands");
        assert!((-1.37..-0.2).contains(&x) && y.abs() < 0.3, "landed at {x}, {y}");
        assert!(j.why.is_none());
    }

    #[test]
    fn a_late_bat_makes_no_contact_and_says_where() {
        let cal = Calibration::default_cell();
        let (launch, s, t_hit) = ball(&cal);
        let (o, v) = aimed(&cal, &s);
        // 0.3 m to the side until 60 ms after the ball has passed.
        let p = path(t_hit, o, |dt| if dt < 0.06 { s.pos + Vec3::new(0.0, 0.3, 0.0) } else { s.pos + v * dt });
        let j = judge_return(&cal, &cal.propagator(), &launch, START, t_hit, &p);
        assert_eq!(j.fail, Some(ReturnFail::NoContact), "{j:?}");
        assert!(j.why.as_deref().is_some_and(|w| w.starts_with("position")), "{:?}", j.why);
        // A bat that stays far behind the ball's path never meets it.
        let p = path(t_hit, o, |_| s.pos + Vec3::new(0.4, 0.0, 0.0));
        let j = judge_return(&cal, &cal.propagator(), &launch, START, t_hit, &p);
        assert_eq!(j.fail, Some(ReturnFail::NoContact));
        assert!(j.why.as_deref().is_some_and(|w| w.starts_with("timing")), "{:?}", j.why);
    }

    #[test]
    fn a_face_too_open_sends_it_long_and_says_by_how_much() {
        let cal = Calibration::default_cell();
        let (launch, s, t_hit) = ball(&cal);
        let (o, v) = aimed(&cal, &s);
        let open = EulerZyx { b: o.b + 15f64.to_radians(), ..o };
        let p = path(t_hit, open, |dt| s.pos + v * dt);
        let j = judge_return(&cal, &cal.propagator(), &launch, START, t_hit, &p);
        assert_eq!(j.fail, Some(ReturnFail::Long), "{j:?}");
        let why = j.why.expect("a reason");
        assert!(why.starts_with("angle") && why.contains("too open"), "{why}");
        let [lo, hi] = j.contact.unwrap().returning_tilt_deg.expect("some tilt returns it");
        assert!(lo <= o.b.to_degrees() + 1.0 && o.b.to_degrees() - 1.0 <= hi, "{lo}…{hi} vs {}", o.b.to_degrees());
    }

    #[test]
    fn the_spin_window_is_the_spin_the_stroke_was_aimed_for() {
        let cal = Calibration::default_cell();
        let (launch, s, t_hit) = ball(&cal);
        let window = |aimed_for: &BallState| {
            let (o, v) = aimed(&cal, aimed_for);
            let p = path(t_hit, o, |dt| s.pos + v * dt);
            let j = judge_return(&cal, &cal.propagator(), &launch, START, t_hit, &p);
            let w = j.contact.and_then(|c| c.spin_window).expect("some spin returns it");
            assert_eq!(j.returned(), w[0] <= 1.0 && 1.0 <= w[1], "{w:?} {j:?}");
            w
        };
        // Aimed for the ball itself: its own spin is inside.
        let [lo, hi] = window(&s);
        assert!(lo < 1.0 && 1.0 < hi, "{lo}…{hi}");
        // Aimed for half again its spin: the window moves up with it.
        let [lo, hi] = window(&BallState { spin: s.spin * 1.5, ..s });
        assert!(lo <= 1.5 && 1.5 <= hi && lo > 1.0, "{lo}…{hi}");
    }
}
