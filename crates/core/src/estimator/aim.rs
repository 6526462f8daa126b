//! Aiming the return: the face tilt and heading that send the ball, hit by
//! the planned bat velocity at the predicted hitting point with its
//! predicted spin, onto a target on the opponent's half — the racket
//! contact model ([`RacketModel`]) inverted through the return's flight.
//!
//! The unknowns are the face's tilt θ (the elevation of its normal, the
//! Euler angle b in T) and its heading ψ (the angle a); the bat moves along
//! the face's normal, through the ball, at the slowest of [`SPEED_STEPS`]
//! speeds (`strike.aim_bat_speed`) that lands the ball. For a guess, the
//! contact model gives the ball's velocity and spin after the hit, and the
//! flight model flies it (RK4 at [`AIM_STEP`]) down to the table's height;
//! a quasi-Newton step (Broyden's update of a finite-difference Jacobian)
//! moves (θ, ψ) so the landing point meets the target. A return that would
//! not clear the net by [`NET_CLEARANCE`] is re-aimed [`DEEPER`] further
//! back. θ stays within `strike.aim_tilt_deg`.
//!
//! Bounded and allocation-free: at most [`AIM_FLIGHTS`] flights per speed,
//! each of at most [`AIM_T_MAX`]; a plan refined for the same ball starts
//! from the last aim (its speed, face and Jacobian, or one speed slower),
//! so a refinement usually costs one or two flights, and none when the
//! prediction has hardly moved.

use crate::calib::StrikeCalib;
use crate::physics::{BallState, Propagator, RacketModel, Vec3};

/// RK4 step of the return's flight while aiming, s (RK4 at 10 ms is within
/// a millimetre of the 4 ms propagator over a return).
pub(crate) const AIM_STEP: f64 = 0.01;
/// Longest return flight followed while aiming, s.
pub(crate) const AIM_T_MAX: f64 = 1.5;
/// Most flights one aim may fly per bat speed.
pub(crate) const AIM_FLIGHTS: usize = 8;
/// A landing this close to the target ends the search, m.
pub(crate) const AIM_TOLERANCE: f64 = 0.03;
/// The least height of the ball's bottom over the net's top, m: room for
/// what the prediction gets wrong (a backspin ball's spin 20 % low drops
/// the return by several centimetres at the net).
pub(crate) const NET_CLEARANCE: f64 = 0.10;
/// How much further back a return that grazes the net is aimed, m.
pub(crate) const DEEPER: f64 = 0.25;
/// A landing this close to the target that does not clear the net moves
/// the target back, m.
const RETARGET_NEAR: f64 = 0.2;
/// Largest change of θ or ψ in one step, rad (10°).
const MAX_STEP: f64 = 0.1745;
/// The heading's bound, rad (the workspace allows ±45° about home).
const MAX_HEADING: f64 = 0.7;
/// ∂x/∂θ above −this (m/rad) is the lob side of the landing's turn.
const LOB_SLOPE: f64 = 0.5;
/// Finite-difference step for the first Jacobian, rad (1°).
const FD_STEP: f64 = 0.01745;

/// Where a return comes down.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Landing {
    /// Where the ball's centre comes down to one radius over the table, m.
    pub x: f64,
    /// …and its y, m.
    pub y: f64,
    /// Height of the ball's bottom over the net's top where it crosses
    /// x = 0, m (−∞ when it never does).
    pub over_net: f64,
}

/// One aim: the face and where the model says the ball lands.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Aim {
    /// Face tilt θ (Euler b in T), rad: > 0 open.
    pub tilt: f64,
    /// Face heading ψ (Euler a in T), rad: the face normal's horizontal
    /// part points along (−cos ψ, −sin ψ).
    pub heading: f64,
    /// Where the return lands in the model.
    pub landing: Landing,
    /// Bat speed, m/s.
    pub speed: f64,
    /// Which of the [`SPEED_STEPS`] speeds.
    pub speed_step: usize,
    /// The predicted ball it was aimed for.
    pub ball: BallState,
    /// The target aimed at (moved back where the net was in the way), m.
    pub target: [f64; 2],
    /// The landing is within [`AIM_TOLERANCE`] of the target and the net
    /// is cleared.
    pub converged: bool,
    /// ∂(landing x, y)/∂(θ, ψ), kept for the next refinement.
    jacobian: [[f64; 2]; 2],
}

/// The face's outward normal for tilt θ and heading ψ (Euler a = ψ,
/// b = θ in T; [`crate::plan::EulerZyx::face_normal`]).
pub fn face_normal(tilt: f64, heading: f64) -> Vec3 {
    let (st, ct) = tilt.sin_cos();
    let (sp, cp) = heading.sin_cos();
    Vec3::new(-cp * ct, -sp * ct, st)
}

/// The bat's velocity for tilt θ and heading ψ at `speed`: along the
/// face's normal, through the ball. (Moving horizontally instead, an open
/// face slides down past the ball and a closed one up, which drives a slow
/// backspin ball into the net and lifts topspin further.)
pub fn bat_velocity(tilt: f64, heading: f64, speed: f64) -> Vec3 {
    face_normal(tilt, heading) * speed
}

/// Flies a return from `s` (just after the hit) until its centre comes
/// down to one radius over the table (a lob still up after [`AIM_T_MAX`]
/// "lands" where it is then, so the landing moves continuously with the
/// stroke); `None` if the state stops being finite.
pub fn fly(prop: &Propagator, s: &BallState) -> Option<Landing> {
    let r = prop.flight.radius();
    let net_top = prop.table.net_height;
    let mut s = *s;
    let mut over_net = f64::NEG_INFINITY;
    let mut t = 0.0;
    while t < AIM_T_MAX {
        let next = prop.rk4(&s, AIM_STEP);
        if !next.is_finite() {
            return None;
        }
        if (s.pos.x > 0.0) != (next.pos.x > 0.0) {
            let u = s.pos.x / (s.pos.x - next.pos.x);
            over_net = s.pos.z + u * (next.pos.z - s.pos.z) - r - net_top;
        }
        if next.pos.z <= r && next.vel.z < 0.0 {
            let u = ((s.pos.z - r) / (s.pos.z - next.pos.z)).clamp(0.0, 1.0);
            let p = s.pos + (next.pos - s.pos) * u;
            return Some(Landing { x: p.x, y: p.y, over_net });
        }
        s = next;
        t += AIM_STEP;
    }
    Some(Landing { x: s.pos.x, y: s.pos.y, over_net })
}

/// Where the ball `ball` lands when the face has tilt θ and heading ψ and
/// the bat moves at `speed` (`None`: no contact, or no landing).
pub fn landing(
    prop: &Propagator,
    racket: &RacketModel,
    ball: &BallState,
    tilt: f64,
    heading: f64,
    speed: f64,
) -> Option<Landing> {
    let n = face_normal(tilt, heading);
    let impact = racket.hit(ball, &n, &(n * speed))?;
    fly(prop, &impact.after)
}

/// What the aim may vary: the face's tilt (rad) and the bat's speed (m/s).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct AimBounds {
    /// Tilt θ from most closed (< 0) to most open (> 0), rad.
    pub tilt: (f64, f64),
    /// Bat speed from the stroke's own to the fastest allowed, m/s.
    pub speed: (f64, f64),
}

impl AimBounds {
    /// The cell's bounds: `strike.aim_tilt_deg` and `strike.aim_bat_speed`.
    pub fn of(cal: &StrikeCalib) -> Self {
        let [closed, open] = cal.aim_tilt_deg.map(f64::to_radians);
        let [slow, fast] = cal.aim_bat_speed;
        AimBounds { tilt: (closed, open), speed: (slow, fast.max(slow)) }
    }

    /// The `k`-th of the [`SPEED_STEPS`] bat speeds, slowest first.
    fn speed(&self, k: usize) -> f64 {
        let (lo, hi) = self.speed;
        lo + (hi - lo) * k as f64 / (SPEED_STEPS - 1) as f64
    }
}

/// Bat speeds tried, slowest first: the slowest bat that lands the ball
/// sends it back slowest, and the slower the return, the less its landing
/// moves with what the prediction got wrong (a fast topspin ball's spin is
/// known to 10–15 % at best: its lift saturates). A faster bat only where
/// the face alone cannot land the ball (slow backspin).
pub(crate) const SPEED_STEPS: usize = 4;

/// A new prediction this close to the last aim's keeps that aim: position,
/// m; velocity, m/s; spin, rad/s (each moves the landing by under 1–3 cm).
const REAIM_POS: f64 = 0.005;
const REAIM_VEL: f64 = 0.02;
const REAIM_SPIN: f64 = 5.0;

/// A face this far inside its bounds may try the next slower bat, rad
/// (10°); nearer a bound, the slower bat would want a face beyond it.
const SLOWER_MARGIN: f64 = 0.1745;

/// Aims the return of `ball` (the predicted state at the hit) at
/// `target` (x, y in T), starting from `warm` (the last aim for this ball)
/// or from tilt `tilt0` and the heading at the target.
pub fn aim(
    bounds: &AimBounds,
    target: [f64; 2],
    prop: &Propagator,
    racket: &RacketModel,
    ball: &BallState,
    tilt0: f64,
    warm: Option<&Aim>,
) -> Aim {
    let (lo, hi) = bounds.tilt;
    if let Some(w) = warm
        && (w.ball.pos - ball.pos).norm() < REAIM_POS
        && (w.ball.vel - ball.vel).norm() < REAIM_VEL
        && (w.ball.spin - ball.spin).norm() < REAIM_SPIN
    {
        return *w;
    }
    let clamp = |p: [f64; 2]| [p[0].clamp(lo, hi), p[1].clamp(-MAX_HEADING, MAX_HEADING)];
    let mut target = warm.map_or(target, |w| w.target);
    let heading = (ball.pos.y - target[1]).atan2(ball.pos.x - target[0]);
    let mut flights = 0;
    // Start at the last aim's speed, or one slower where its face had room.
    let first = warm.map_or(0, |w| {
        let room = (w.tilt - lo).min(hi - w.tilt);
        if w.speed_step > 0 && room > SLOWER_MARGIN { w.speed_step - 1 } else { w.speed_step }
    });
    let mut last = None;
    for k in first..SPEED_STEPS {
        let speed = bounds.speed(k);
        let fly_at = |p: &[f64; 2], flights: &mut usize| {
            *flights += 1;
            landing(prop, racket, ball, p[0], p[1], speed)
        };
        // A landing as a point (no contact: nowhere useful, far along +x).
        let point = |l: Option<Landing>| l.map_or([100.0, 0.0], |l| [l.x, l.y]);
        // From the last aim at its own speed; else afresh (from the rule's
        // tilt, with a finite-difference Jacobian).
        let resume = warm.filter(|w| w.speed_step == k);
        let mut p = clamp(resume.map_or([tilt0, heading], |w| [w.tilt, w.heading]));
        let mut here = fly_at(&p, &mut flights);
        let mut j = match resume {
            Some(w) => w.jacobian,
            None => {
                let f0 = point(here);
                let ft = point(fly_at(&[p[0] + FD_STEP, p[1]], &mut flights));
                let fh = point(fly_at(&[p[0], p[1] + FD_STEP], &mut flights));
                [
                    [(ft[0] - f0[0]) / FD_STEP, (fh[0] - f0[0]) / FD_STEP],
                    [(ft[1] - f0[1]) / FD_STEP, (fh[1] - f0[1]) / FD_STEP],
                ]
            }
        };
        let mut best: Option<(f64, [f64; 2], Landing)> = None;
        loop {
            let f = point(here);
            let clear = here.is_some_and(|l| l.over_net >= NET_CLEARANCE);
            let mut res = [f[0] - target[0], f[1] - target[1]];
            if !clear && res[0].hypot(res[1]) < RETARGET_NEAR && target[0] - DEEPER > -prop.table.length / 2.0 {
                // On target but under (or into) the net: aim further back.
                target[0] -= DEEPER;
                res[0] += DEEPER;
            }
            let err = res[0].hypot(res[1]);
            if let Some(l) = here
                && clear
                && best.is_none_or(|b| err < b.0)
            {
                best = Some((err, p, l));
            }
            if (clear && err < AIM_TOLERANCE) || flights >= AIM_FLIGHTS * (k + 1 - first) {
                break;
            }
            // Newton step on the current Jacobian, bounded. Opening the face
            // sends the ball longer (∂x/∂θ < 0) until the return becomes a
            // lob that comes down shorter again. On that side, close the face
            // by a full step; at the turn, a ball still short of the target
            // is out of this speed's reach.
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            let slope = j[0][0];
            if slope.abs() <= LOB_SLOPE && res[0] > 0.0 {
                break;
            }
            let d = if slope > -LOB_SLOPE || !(det.abs() > 1e-9) {
                [-MAX_STEP, if j[1][1].abs() > 1e-9 { (-res[1] / j[1][1]).clamp(-MAX_STEP, MAX_STEP) } else { 0.0 }]
            } else {
                [
                    (-(j[1][1] * res[0] - j[0][1] * res[1]) / det).clamp(-MAX_STEP, MAX_STEP),
                    (-(-j[1][0] * res[0] + j[0][0] * res[1]) / det).clamp(-MAX_STEP, MAX_STEP),
                ]
            };
            let next = clamp([p[0] + d[0], p[1] + d[1]]);
            let step = [next[0] - p[0], next[1] - p[1]];
            let norm2 = step[0] * step[0] + step[1] * step[1];
            if norm2 < 1e-12 {
                break; // against a bound
            }
            let there = fly_at(&next, &mut flights);
            let g = point(there);
            // Broyden: J += (Δf − J Δp) Δpᵀ / |Δp|².
            let df = [g[0] - f[0], g[1] - f[1]];
            for (i, row) in j.iter_mut().enumerate() {
                let miss = df[i] - (row[0] * step[0] + row[1] * step[1]);
                for (jj, x) in row.iter_mut().enumerate() {
                    *x += miss * step[jj] / norm2;
                }
            }
            p = next;
            here = there;
        }
        let aim = match best {
            Some((err, bp, l)) => Aim {
                tilt: bp[0],
                heading: bp[1],
                speed,
                speed_step: k,
                ball: *ball,
                landing: l,
                target,
                converged: err < AIM_TOLERANCE,
                jacobian: j,
            },
            None => Aim {
                tilt: p[0],
                heading: p[1],
                speed,
                speed_step: k,
                ball: *ball,
                landing: here.unwrap_or(Landing { x: f64::NAN, y: f64::NAN, over_net: f64::NEG_INFINITY }),
                target,
                converged: false,
                jacobian: j,
            },
        };
        if aim.converged {
            return aim;
        }
        last = Some(aim);
    }
    last.expect("at least one speed is tried")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;
    use crate::physics::{Event, StopAt};

    fn cell() -> (AimBounds, [f64; 2], Propagator, RacketModel) {
        let cal = Calibration::default_cell();
        let bounds = AimBounds::of(&cal.strike);
        (bounds, cal.strike.aim_target, cal.propagator(), cal.racket_model())
    }

    /// The search's start, as the estimator gives it: the paper's β.
    fn tilt0(b: &BallState) -> f64 {
        -crate::estimator::stroke::paper_beta(&Calibration::default_cell().strike, &b.spin)
    }

    /// Balls at the hitting plane as the launcher's settings bring them
    /// (`topspin sim`: truth.hit).
    fn balls() -> [BallState; 5] {
        let at = |y: f64, z: f64, v: [f64; 3], w: [f64; 3]| {
            BallState::new(Vec3::new(1.6, y, z), Vec3::from(v), Vec3::from(w))
        };
        [
            at(0.0, 0.25, [7.4, -0.2, 1.1], [14.0, 547.0, -13.0]), // topspin-high
            at(0.3, 0.20, [3.4, -0.4, -0.4], [-30.0, -239.0, 3.0]), // backspin-medium
            at(-0.4, 0.22, [4.9, -1.8, 0.1], [7.0, -32.0, -429.0]), // sidespin-high
            at(0.5, 0.34, [3.8, 1.0, -0.3], [-59.0, 213.0, -6.0]), // topspin-low
            at(-0.2, 0.35, [2.9, 0.4, 0.4], [-59.0, -1.0, 175.0]), // sidespin-low
        ]
    }

    #[test]
    fn the_aimed_return_lands_on_the_target_in_the_full_physics() {
        let (bounds, target, prop, racket) = cell();
        for b in balls() {
            let a = aim(&bounds, target, &prop, &racket, &b, tilt0(&b), None);
            assert!(a.converged, "{a:?} for {b:?}");
            // Fly it with the propagator itself (4 ms, events): it clears the
            // net and bounces within 5 cm of the target.
            let n = face_normal(a.tilt, a.heading);
            let mut s = racket.hit(&b, &n, &bat_velocity(a.tilt, a.heading, a.speed)).unwrap().after;
            let mut t = 0.0;
            let e = prop.advance(&mut s, &mut t, &StopAt { t_max: 3.0, hit_plane_x: None, net: true });
            let Event::Bounce { before, .. } = e else { panic!("{e:?} for {b:?}") };
            let miss = (before.pos.x - a.target[0]).hypot(before.pos.y - a.target[1]);
            assert!(miss < 0.05, "landed {:?}, target {:?}", before.pos, a.target);
            assert!(a.target[0] < 0.0 && a.landing.over_net >= NET_CLEARANCE);
            assert!(a.tilt >= bounds.tilt.0 && a.tilt <= bounds.tilt.1);
            assert!(a.speed >= bounds.speed.0 && a.speed <= bounds.speed.1);
        }
    }

    #[test]
    fn topspin_gets_a_closed_face_backspin_an_open_one_and_a_faster_bat() {
        let (bounds, target, prop, racket) = cell();
        let b = balls();
        let top = aim(&bounds, target, &prop, &racket, &b[0], tilt0(&b[0]), None);
        let back = aim(&bounds, target, &prop, &racket, &b[1], tilt0(&b[1]), None);
        assert!(
            top.tilt < -0.3 && back.tilt > 0.3,
            "top {:.1}°, back {:.1}°",
            top.tilt.to_degrees(),
            back.tilt.to_degrees()
        );
        // The slow backspin ball needs more than the face: a faster bat.
        assert!(top.speed < back.speed, "{top:?} {back:?}");
        // A ball on the +y side is sent back towards the middle: the face
        // turns towards −y (ψ > 0), and from −y towards +y.
        let plus = aim(&bounds, target, &prop, &racket, &b[3], tilt0(&b[3]), None);
        let minus = aim(&bounds, target, &prop, &racket, &b[4], tilt0(&b[4]), None);
        assert!(plus.heading > 0.0 && minus.heading < 0.0, "{plus:?} {minus:?}");
    }

    #[test]
    fn a_refinement_starts_from_the_last_aim() {
        let (bounds, target, prop, racket) = cell();
        let b = balls()[0];
        let first = aim(&bounds, target, &prop, &racket, &b, tilt0(&b), None);
        let mut moved = b;
        moved.pos.z += 0.01;
        moved.vel.x += 0.05;
        let again = aim(&bounds, target, &prop, &racket, &moved, tilt0(&moved), Some(&first));
        assert!(again.converged);
        assert!((again.tilt - first.tilt).abs() < 0.05);
        assert_eq!(again.speed_step, first.speed_step);
    }

    #[test]
    fn the_aim_stays_within_its_bounds() {
        let (bounds, target, prop, racket) = cell();
        // Heavy backspin, slow and low: wants more than the bounds give.
        let b = BallState::new(Vec3::new(1.6, 0.0, 0.16), Vec3::new(2.0, 0.0, -1.0), Vec3::new(0.0, -900.0, 0.0));
        let a = aim(&bounds, target, &prop, &racket, &b, tilt0(&b), None);
        assert!(a.tilt >= bounds.tilt.0 && a.tilt <= bounds.tilt.1, "{a:?}");
        assert!(a.heading.abs() <= MAX_HEADING && a.speed <= bounds.speed.1, "{a:?}");
    }
}
