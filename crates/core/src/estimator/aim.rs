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
//! back, and so is one that would not clear it were the ball's spin
//! [`NET_SPIN_SIGMAS`] σ above its estimate (σ of ln(spin): the spin
//! prior's hedge for the ball, no less than a flight alone may hide, or the
//! camera's): a saturated lift reads fast spin low, and more backspin
//! than the aim knew drops the return into the net. Where no face lands the target so moved back, the
//! deepest clear landing found is the aim. θ stays within
//! `strike.aim_tilt_deg`.
//!
//! Where the arm is known ([`AimBounds::within`], from the estimator's
//! [`ReachMap`]), θ also stays within the tilts the arm can present at the
//! hitting point, and each speed is capped at what its axes deliver along
//! the face's normal there ([`ArmReach::cap`]): the generator would slow a
//! faster bat, and the return would land short of where it was aimed.
//!
//! Bounded and allocation-free: at most [`AIM_BUDGET`] flights per plan,
//! each of at most [`AIM_T_MAX`]. The search is resumed by the next plan
//! for the same ball (its face, speed and Jacobian): an unconverged aim is
//! the best face found so far, a refinement usually costs one or two
//! flights, and none when the prediction has hardly moved.
//!
//! A search climbs to a faster bat, and moves its target back, for the
//! prediction it had then; when the prediction moves (a spin estimate
//! that jumps, the camera's spin arriving) that bat and target can stay
//! where no face lands the ball. So [`Searches`] runs a fresh search for
//! the latest prediction beside any search that has climbed, and takes
//! it over once it lands the ball with a slower bat (or the other has
//! not landed it at all). One that lands it no better, or climbs as far
//! without landing it, gives way; another starts when the prediction has
//! moved on ([`FRESH_AGAIN`]). At most twice the plan's budget of flights.

use crate::calib::StrikeCalib;
use crate::motion::reach::{ReachMap, SpeedCaps};
use crate::physics::{BallState, Propagator, RacketModel, Vec3};

/// RK4 step of the return's flight while aiming, s: its landing is within
/// 4 mm of the 4 ms propagator's for every kind of return (2 mm at 20 ms,
/// 9 mm at 40 ms), at under a seventh of the cost
/// (`every_kind_of_return_lands_within_a_centimetre_of_the_propagators`).
pub(crate) const AIM_STEP: f64 = 0.03;
/// Longest return flight followed while aiming, s.
pub(crate) const AIM_T_MAX: f64 = 1.5;
/// Returns flown per plan at most (the estimator's hot path: a flight
/// costs a few microseconds); an aim not converged within it goes on with
/// the next observation's plan.
pub(crate) const AIM_BUDGET: usize = 3;
/// Returns flown at one speed without landing the ball before a faster
/// bat is tried.
pub(crate) const LEVEL_FLIGHTS: usize = 10;
/// A landing this close to the target ends the search, m.
pub(crate) const AIM_TOLERANCE: f64 = 0.03;
/// The least height of the ball's bottom over the net's top, m: room for
/// what the prediction gets wrong (a backspin ball's spin 20 % low drops
/// the return by several centimetres at the net). Every centimetre of it
/// also sends the return deeper, towards the end line, where a topspin
/// ball's spin read low sends it long: 5 cm returned more than 10 cm in
/// every world measured (`docs/physics.md`, § The racket).
pub(crate) const NET_CLEARANCE: f64 = 0.05;
/// How far above its estimate, in σ of ln(spin) (the spin prior's hedge
/// for the ball, or the camera's), the spin may be and a return still clear
/// the net by [`NET_CLEARANCE`]: more backspin drops the return, and where
/// the lift saturates the flight reads fast spin low. Two: with the
/// flight's hedge (σ 0.45 at S 0.4, 0.6 at 0.8) that is ×2.5 and ×3.3,
/// what real balls' flights hide at their worst (read at 0.53 of 40–80
/// rev/s, 0.31 above 80: `docs/physics.md`); a ball in the net is lost
/// outright, one aimed deeper than it needed rarely.
pub(crate) const NET_SPIN_SIGMAS: f64 = 2.0;
/// How much further back a return that grazes the net is aimed, m.
pub(crate) const DEEPER: f64 = 0.25;
/// A landing this close to the target that does not clear the net moves
/// the target back, m.
const RETARGET_NEAR: f64 = 0.2;
/// Largest change of θ or ψ in one step, rad (10°).
const MAX_STEP: f64 = 0.1745;
/// The heading's bound, rad: the workspace allows ±45° about home
/// (`workspace.abc_range_deg`), strokes keep 10° inside it
/// ([`crate::motion::margins::ORIENTATION_MARGIN_RAD`]).
const MAX_HEADING: f64 = 0.61;
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

/// One aim: the face and where the model says the ball lands, and the
/// search behind it (resumed by the next refinement).
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
    /// Which of the `SPEED_STEPS` speeds.
    pub speed_step: usize,
    /// The predicted ball it was aimed for.
    pub ball: BallState,
    /// Returns flown by the call that made this aim.
    pub flights: usize,
    /// The target aimed at (moved back where the net was in the way), m.
    pub target: [f64; 2],
    /// The landing is within `AIM_TOLERANCE` of the target and the net
    /// is cleared.
    pub converged: bool,
    /// Where the search stands: (θ, ψ), the speed step, and ∂(landing x,
    /// y)/∂(θ, ψ) there (`None`: to be measured).
    search: [f64; 2],
    level: usize,
    jacobian: Option<[[f64; 2]; 2]>,
    /// Returns flown at this speed since it last landed the ball.
    tries: usize,
    /// The face has landed the ball at least once.
    settled: bool,
    /// Until it has: the nearest clear landing so far (miss, face, speed
    /// step, landing).
    best: Option<(f64, [f64; 2], usize, Landing)>,
}

/// The aim of one ball across its plans: the search the plans resume
/// and, where that one has climbed to a faster bat or moved its target
/// back, a fresh search for the latest prediction beside it.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub(crate) struct Searches {
    /// The search whose face the plans send.
    current: Option<Aim>,
    /// The fresh one, while there is one.
    fresh: Option<Aim>,
    /// The ball the latest fresh search began for: another begins once
    /// the prediction has moved [`FRESH_AGAIN`] times the re-aim bounds
    /// from it.
    fresh_for: Option<BallState>,
}

/// How far, in multiples of the re-aim bounds (`REAIM_*`), the prediction
/// moves before a fresh search that gave way is tried again: 10–30 cm of
/// landing.
const FRESH_AGAIN: f64 = 10.0;

impl Searches {
    /// Aims `ball` as [`aim`] does, resuming the current search; where
    /// that one has climbed (a faster bat than the slowest, or a target
    /// moved back from `target`), also resumes or starts the fresh
    /// search, each within `budget` flights, and takes the fresh one
    /// over once it lands the ball with a slower bat, or the current
    /// one has not landed it.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn step(
        &mut self,
        bounds: &AimBounds,
        target: [f64; 2],
        prop: &Propagator,
        racket: &RacketModel,
        ball: &BallState,
        spin_sigma: f64,
        tilt0: f64,
        budget: usize,
    ) -> Aim {
        let mut a = aim(bounds, target, prop, racket, ball, spin_sigma, tilt0, self.current.as_ref(), budget);
        if a.level == 0 && a.target == target {
            *self = Searches { current: Some(a), ..Searches::default() };
            return a;
        }
        let again = self.fresh_for.is_none_or(|b| !near(&b, ball, FRESH_AGAIN));
        if self.fresh.is_none() && again {
            self.fresh_for = Some(*ball);
        }
        if self.fresh.is_some() || again {
            let f = aim(bounds, target, prop, racket, ball, spin_sigma, tilt0, self.fresh.as_ref(), budget);
            let flights = a.flights + f.flights;
            // It takes over where it lands the ball with a slower bat (or
            // the other has not landed it); it gives way where it lands it
            // no better, or climbs as far without landing it.
            let (takes_over, gives_way) = if f.converged {
                (!a.converged || f.speed_step < a.speed_step, true)
            } else {
                (false, f.level >= a.level)
            };
            if takes_over {
                a = f;
            }
            self.fresh = (!gives_way).then_some(f);
            a.flights = flights;
        }
        self.current = Some(a);
        a
    }
}

/// The face's outward normal for tilt θ and heading ψ (Euler a = ψ,
/// b = θ in T; [`crate::geometry::EulerZyx::face_normal`]).
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

/// One return of [`fly_all`].
#[cfg(test)]
pub(crate) fn fly(prop: &Propagator, s: &BallState) -> Option<Landing> {
    let [landing] = fly_all(prop, [Some(*s)]);
    landing
}

/// Flies returns from just after their hits (`None`: no return) until
/// each ball's centre comes down to one radius over the table (a lob
/// still up after [`AIM_T_MAX`] "lands" where it is then, so the landing
/// moves continuously with the stroke); `None` where the state stops
/// being finite. Several fly in lockstep: each takes the steps it would
/// alone, and their independent arithmetic overlaps in the processor (an
/// RK4 step waits on its own square root and division).
fn fly_all<const N: usize>(prop: &Propagator, from: [Option<BallState>; N]) -> [Option<Landing>; N] {
    let r = prop.flight.radius();
    let net_top = prop.table.net_height;
    let mut flying = from;
    let mut out = [None; N];
    let mut over_net = [f64::NEG_INFINITY; N];
    let mut t = 0.0;
    while t < AIM_T_MAX && flying.iter().any(Option::is_some) {
        for k in 0..N {
            let Some(s) = flying[k] else { continue };
            let next = prop.rk4(&s, AIM_STEP);
            flying[k] = None;
            if !next.is_finite() {
                continue;
            }
            if (s.pos.x > 0.0) != (next.pos.x > 0.0) {
                let u = s.pos.x / (s.pos.x - next.pos.x);
                over_net[k] = s.pos.z + u * (next.pos.z - s.pos.z) - r - net_top;
            }
            if next.pos.z <= r && next.vel.z < 0.0 {
                let u = ((s.pos.z - r) / (s.pos.z - next.pos.z)).clamp(0.0, 1.0);
                let p = s.pos + (next.pos - s.pos) * u;
                out[k] = Some(Landing { x: p.x, y: p.y, over_net: over_net[k] });
                continue;
            }
            flying[k] = Some(next);
        }
        t += AIM_STEP;
    }
    for (k, s) in flying.iter().enumerate() {
        if let Some(s) = s {
            out[k] = Some(Landing { x: s.pos.x, y: s.pos.y, over_net: over_net[k] });
        }
    }
    out
}

/// The landing's Jacobian in (θ, ψ) from the landings at the face `f0`
/// and one [`FD_STEP`] further in θ (`ft`) and in ψ (`fh`).
fn fd_jacobian(f0: [f64; 2], ft: [f64; 2], fh: [f64; 2]) -> [[f64; 2]; 2] {
    [[(ft[0] - f0[0]) / FD_STEP, (fh[0] - f0[0]) / FD_STEP], [(ft[1] - f0[1]) / FD_STEP, (fh[1] - f0[1]) / FD_STEP]]
}

/// Where the ball `ball` lands when the face has tilt θ and heading ψ and
/// the bat moves at `speed` (`None`: no contact, or no landing).
pub(crate) fn landing(
    prop: &Propagator,
    racket: &RacketModel,
    ball: &BallState,
    tilt: f64,
    heading: f64,
    speed: f64,
) -> Option<Landing> {
    let [landing] = landings(prop, racket, ball, [(tilt, heading, speed)]);
    landing
}

/// [`landing`] for several faces (tilt, heading, speed), flown together.
fn landings<const N: usize>(
    prop: &Propagator,
    racket: &RacketModel,
    ball: &BallState,
    faces: [(f64, f64, f64); N],
) -> [Option<Landing>; N] {
    let after = faces.map(|(tilt, heading, speed)| {
        let n = face_normal(tilt, heading);
        racket.hit(ball, &n, &(n * speed)).map(|impact| impact.after)
    });
    fly_all(prop, after)
}

/// What the aim may vary: the face's tilt (rad) and the bat's speed (m/s).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct AimBounds {
    /// Tilt θ from most closed (< 0) to most open (> 0), rad.
    pub tilt: (f64, f64),
    /// Bat speed from the stroke's own to the fastest allowed, m/s.
    pub speed: (f64, f64),
    /// What the arm delivers at the hitting point (`None`: no arm, the
    /// bounds alone).
    pub arm: Option<ArmReach>,
}

/// The fastest bat the arm delivers along the face's normal at one
/// hitting point, per face tilt ([`ReachMap::caps_at`]; 0: it cannot
/// present that face there).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ArmReach {
    /// The first tilt, rad.
    pub tilt0: f64,
    /// The step between tilts, rad.
    pub step: f64,
    /// How many of `caps` hold tilts.
    pub n: usize,
    /// The fastest bat per tilt, m/s.
    pub caps: SpeedCaps,
    /// The blade's roll (Euler c in T) that gives it, per tilt, rad.
    pub rolls: SpeedCaps,
}

impl ArmReach {
    /// The map's caps at (y, z).
    pub fn at(map: &ReachMap, y: f64, z: f64) -> Self {
        let (caps, rolls) = map.caps_at(y, z);
        ArmReach {
            tilt0: map.tilt(0),
            step: crate::motion::reach::REACH_TILT_STEP_DEG.to_radians(),
            n: map.tilts(),
            caps,
            rolls,
        }
    }

    /// The blade's roll for tilt θ: the nearest tilt's.
    pub fn roll(&self, tilt: f64) -> f64 {
        if self.n == 0 {
            return 0.0;
        }
        let k = ((tilt - self.tilt0) / self.step).round().clamp(0.0, (self.n - 1) as f64) as usize;
        self.rolls[k]
    }

    /// The fastest bat at tilt θ: linear between the two tilts around it,
    /// 0 if either cannot be presented.
    pub fn cap(&self, tilt: f64) -> f64 {
        if self.n == 0 {
            return 0.0;
        }
        let u = ((tilt - self.tilt0) / self.step).clamp(0.0, (self.n - 1) as f64);
        let k = (u.floor() as usize).min(self.n - 1);
        let k1 = (k + 1).min(self.n - 1);
        let (a, b) = (self.caps[k], self.caps[k1]);
        if a <= 0.0 || b <= 0.0 {
            return 0.0;
        }
        a + (b - a) * (u - k as f64)
    }

    /// The longest run of tilts the arm can present (the one nearer an
    /// upright face among equals), rad; `None`: none.
    pub fn tilts(&self) -> Option<(f64, f64)> {
        let mut best: Option<(usize, usize)> = None;
        let mut k = 0;
        while k < self.n {
            if self.caps[k] <= 0.0 {
                k += 1;
                continue;
            }
            let start = k;
            while k < self.n && self.caps[k] > 0.0 {
                k += 1;
            }
            let run = (start, k - 1);
            let tilt = |i: usize| self.tilt0 + i as f64 * self.step;
            let off = |r: (usize, usize)| tilt(r.0).max(-tilt(r.1)).max(0.0);
            let better = best.is_none_or(|b| {
                let (len, blen) = (run.1 - run.0, b.1 - b.0);
                len > blen || (len == blen && off(run) < off(b))
            });
            if better {
                best = Some(run);
            }
        }
        best.map(|(a, b)| (self.tilt0 + a as f64 * self.step, self.tilt0 + b as f64 * self.step))
    }
}

impl AimBounds {
    /// The cell's bounds: `strike.aim_tilt_deg` and `strike.aim_bat_speed`.
    pub fn of(cal: &StrikeCalib) -> Self {
        let [closed, open] = cal.aim_tilt_deg.map(f64::to_radians);
        let [slow, fast] = cal.aim_bat_speed;
        AimBounds { tilt: (closed, open), speed: (slow, fast.max(slow)), arm: None }
    }

    /// These bounds where the arm has `arm`: the tilts it can present
    /// (where it can present any), each speed at most what it delivers.
    pub fn within(&self, arm: ArmReach) -> Self {
        let tilt = match arm.tilts() {
            Some((lo, hi)) if lo.max(self.tilt.0) <= hi.min(self.tilt.1) => (lo.max(self.tilt.0), hi.min(self.tilt.1)),
            _ => self.tilt,
        };
        AimBounds { tilt, arm: Some(arm), ..*self }
    }

    /// The `k`-th of the `SPEED_STEPS` bat speeds, slowest first, at
    /// face tilt θ: no faster than the arm delivers there (the generator
    /// would slow it to that).
    pub fn speed(&self, k: usize, tilt: f64) -> f64 {
        let (lo, hi) = self.speed;
        let v = lo + (hi - lo) * k as f64 / (SPEED_STEPS - 1) as f64;
        match self.arm {
            Some(a) if a.cap(tilt) > 0.0 => v.min(a.cap(tilt)),
            _ => v,
        }
    }
}

/// Bat speeds tried, slowest first: the slowest bat that lands the ball
/// sends it back slowest, and the slower the return, the less its landing
/// moves with what the prediction got wrong (a fast topspin ball's spin is
/// known to 10–15 % at best: its lift saturates). A faster bat only where
/// the face alone cannot land the ball (slow backspin).
pub(crate) const SPEED_STEPS: usize = 4;

/// A new prediction this close to the last converged aim's keeps that
/// aim: position, m; velocity, m/s; spin, rad/s (each moves the landing by
/// under 1–3 cm).
const REAIM_POS: f64 = 0.005;
const REAIM_VEL: f64 = 0.02;
const REAIM_SPIN: f64 = 5.0;

/// `b` is within `times` the re-aim bounds of `a`.
fn near(a: &BallState, b: &BallState, times: f64) -> bool {
    (a.pos - b.pos).norm() < REAIM_POS * times
        && (a.vel - b.vel).norm() < REAIM_VEL * times
        && (a.spin - b.spin).norm() < REAIM_SPIN * times
}

/// Aims the return of `ball` (the predicted state at the hit) at
/// `target` (x, y in T), its spin known to `spin_sigma` (σ of ln(spin);
/// 0: exactly): resumes the search of `warm` (the last aim for this
/// ball) or starts one from tilt `tilt0` and the heading at the target,
/// and flies at most `budget` returns (at least 3 for a start);
/// an aim not yet converged is the best face found so far, and the next
/// call goes on from where this one stopped.
#[allow(clippy::too_many_arguments)]
pub fn aim(
    bounds: &AimBounds,
    target: [f64; 2],
    prop: &Propagator,
    racket: &RacketModel,
    ball: &BallState,
    spin_sigma: f64,
    tilt0: f64,
    warm: Option<&Aim>,
    budget: usize,
) -> Aim {
    let (lo, hi) = bounds.tilt;
    if let Some(w) = warm
        && w.converged
        && near(&w.ball, ball, 1.0)
    {
        return Aim { flights: 0, ..*w };
    }
    let clamp = |p: [f64; 2]| [p[0].clamp(lo, hi), p[1].clamp(-MAX_HEADING, MAX_HEADING)];
    let configured = target;
    let mut target = warm.map_or(target, |w| w.target);
    // The end line, and whether a target can move back once more before it.
    let end_line = -prop.table.length / 2.0;
    let room_behind = |t: &[f64; 2]| t[0] - DEEPER > end_line;
    let start = |target: &[f64; 2]| clamp([tilt0, (ball.pos.y - target[1]).atan2(ball.pos.x - target[0])]);
    let (mut p, mut level, mut jac, mut tries) =
        warm.map_or((start(&target), 0, None, 0), |w| (w.search, w.level, w.jacobian, w.tries));
    let mut left = budget;
    let mut flown = 0;
    // Flies the return of `b` off face `p` at speed step `level`, counted.
    let fly = |b: &BallState, p: &[f64; 2], level: usize, left: &mut usize, flown: &mut usize| {
        *left = left.saturating_sub(1);
        *flown += 1;
        landing(prop, racket, b, p[0], p[1], bounds.speed(level, p[0]))
    };
    // A landing as a point (no contact: nowhere useful, far along +x).
    let point = |l: &Option<Landing>| l.map_or([100.0, 0.0], |l| [l.x, l.y]);
    let mut here: Option<Option<Landing>> = None;
    // The best clear landing of this call: (miss, face, level, landing).
    let mut best: Option<(f64, [f64; 2], usize, Landing)> = warm.and_then(|w| w.best);
    let mut converged = false;
    let mut restarted = false;
    // A face that lands the estimate, found by this call before the spin
    // that may be more than it moved the target back (face, speed step,
    // landing).
    let mut landed: Option<([f64; 2], usize, Landing)> = None;
    while left > 0 {
        if here.is_none() && jac.is_none() && left >= 3 {
            // A first Jacobian: the face and its two neighbours, flown
            // together.
            let faces = [p, [p[0] + FD_STEP, p[1]], [p[0], p[1] + FD_STEP]];
            let [l0, lt, lh] = landings(prop, racket, ball, faces.map(|f| (f[0], f[1], bounds.speed(level, f[0]))));
            (left, flown) = (left - 3, flown + 3);
            jac = Some(fd_jacobian(point(&l0), point(&lt), point(&lh)));
            here = Some(l0);
        }
        let now = *here.get_or_insert_with(|| fly(ball, &p, level, &mut left, &mut flown));
        let j = match jac {
            Some(j) => j,
            None if left >= 2 => {
                let ft = point(&fly(ball, &[p[0] + FD_STEP, p[1]], level, &mut left, &mut flown));
                let fh = point(&fly(ball, &[p[0], p[1] + FD_STEP], level, &mut left, &mut flown));
                let j = fd_jacobian(point(&now), ft, fh);
                jac = Some(j);
                j
            }
            None => break,
        };
        let f = point(&now);
        let clear = now.is_some_and(|l| l.over_net >= NET_CLEARANCE);
        let mut res = [f[0] - target[0], f[1] - target[1]];
        if !clear && res[0].hypot(res[1]) < RETARGET_NEAR && room_behind(&target) {
            // On target but under (or into) the net: aim further back.
            target[0] -= DEEPER;
            res[0] += DEEPER;
        }
        let err = res[0].hypot(res[1]);
        if let Some(l) = now
            && clear
            && best.is_none_or(|b| err < b.0)
        {
            best = Some((err, p, level, l));
        }
        if clear && err < AIM_TOLERANCE {
            // The spin may be more than its estimate (a saturated lift reads
            // it low): a backspin return must clear the net with that too.
            if spin_sigma > 0.0 && room_behind(&target) {
                if left == 0 {
                    break;
                }
                let more = BallState { spin: ball.spin * (NET_SPIN_SIGMAS * spin_sigma).exp(), ..*ball };
                let l = fly(&more, &p, level, &mut left, &mut flown);
                if l.is_none_or(|l| l.over_net < NET_CLEARANCE) {
                    landed = now.map(|l| (p, level, l));
                    target[0] -= DEEPER;
                    continue;
                }
            }
            converged = true;
            // This speed does it: its count starts again.
            tries = 0;
            flown = 0;
            break;
        }
        // Newton step on the current Jacobian, bounded. Opening the face
        // sends the ball longer (∂x/∂θ < 0) until the return becomes a lob
        // that comes down shorter again. On that side, close the face by a
        // full step; at the turn, a ball still short of the target is out
        // of this speed's reach.
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        let slope = j[0][0];
        let d = if slope.abs() <= LOB_SLOPE && res[0] > 0.0 {
            [0.0, 0.0]
        } else if slope > -LOB_SLOPE || det.abs() <= 1e-9 || det.is_nan() {
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
        let last = level + 1 >= SPEED_STEPS;
        if last
            && d[0] != 0.0
            && step[0] == 0.0
            && target[0] < configured[0]
            && let Some((_, face, at, l)) = best
            && l.x > end_line
        {
            // A target moved back that no face reaches (the fastest bat,
            // the tilt against its bound): the deepest clear landing found.
            (p, level, here, converged) = (face, at, Some(Some(l)), true);
            break;
        }
        if norm2 < 1e-12 || (tries + flown >= LEVEL_FLIGHTS && !last) {
            // Out of reach, against a bound, or not landing it after
            // LEVEL_FLIGHTS: a faster bat, from the start. The fastest
            // against a bound starts again from the start (once a call):
            // the prediction may have moved since it got there.
            if last {
                let from = start(&target);
                if (p[0] - from[0]).abs() + (p[1] - from[1]).abs() < FD_STEP || restarted {
                    break;
                }
                restarted = true;
                p = from;
                jac = None;
                here = None;
                continue;
            }
            level += 1;
            p = start(&target);
            jac = None;
            here = None;
            tries = 0;
            flown = 0;
            continue;
        }
        let there = fly(ball, &next, level, &mut left, &mut flown);
        let g = point(&there);
        // Broyden: J += (Δf − J Δp) Δpᵀ / |Δp|².
        let df = [g[0] - f[0], g[1] - f[1]];
        let mut j = j;
        for (i, row) in j.iter_mut().enumerate() {
            let miss = df[i] - (row[0] * step[0] + row[1] * step[1]);
            for (k, x) in row.iter_mut().enumerate() {
                *x += miss * step[k] / norm2;
            }
        }
        jac = Some(j);
        p = next;
        here = Some(there);
    }
    let unknown = Landing { x: f64::NAN, y: f64::NAN, over_net: f64::NEG_INFINITY };
    // The face: where the search converged; until it does again, the last
    // one that landed the estimate (it landed a ball very like this one);
    // before any, the nearest clear landing found, or the start.
    let settled = converged || landed.is_some() || warm.is_some_and(|w| w.settled);
    let (face, out_level, landing) = match (converged, landed, warm) {
        (true, _, _) => (p, level, here.flatten().unwrap_or(unknown)),
        (false, Some(l), _) => l,
        (false, None, Some(w)) if w.settled => ([w.tilt, w.heading], w.speed_step, w.landing),
        _ => best.map_or((start(&target), 0, unknown), |(_, bp, bl, l)| (bp, bl, l)),
    };
    Aim {
        tilt: face[0],
        heading: face[1],
        landing,
        speed: bounds.speed(out_level, face[0]),
        speed_step: out_level,
        ball: *ball,
        target,
        converged,
        search: p,
        level,
        jacobian: jac,
        tries: tries + flown,
        flights: budget - left,
        settled,
        best: if converged { None } else { best },
    }
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
            let a = aim(&bounds, target, &prop, &racket, &b, 0.0, tilt0(&b), None, 64);
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
        let top = aim(&bounds, target, &prop, &racket, &b[0], 0.0, tilt0(&b[0]), None, 64);
        let back = aim(&bounds, target, &prop, &racket, &b[1], 0.0, tilt0(&b[1]), None, 64);
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
        let plus = aim(&bounds, target, &prop, &racket, &b[3], 0.0, tilt0(&b[3]), None, 64);
        let minus = aim(&bounds, target, &prop, &racket, &b[4], 0.0, tilt0(&b[4]), None, 64);
        assert!(plus.heading > 0.0 && minus.heading < 0.0, "{plus:?} {minus:?}");
    }

    #[test]
    fn a_backspin_return_clears_the_net_with_the_spin_it_may_have_above_its_estimate() {
        let (bounds, target, prop, racket) = cell();
        let back = balls()[1];
        let sigma = 0.25;
        let sure = aim(&bounds, target, &prop, &racket, &back, 0.0, tilt0(&back), None, 64);
        let unsure = aim(&bounds, target, &prop, &racket, &back, sigma, tilt0(&back), None, 64);
        let more = BallState { spin: back.spin * sigma.exp(), ..back };
        let over_net = |a: &Aim, b: &BallState| {
            landing(&prop, &racket, b, a.tilt, a.heading, a.speed).map_or(f64::NEG_INFINITY, |l| l.over_net)
        };
        // Aimed for the estimate alone, a ball with e^σ times the backspin
        // goes into the net. Aimed so that it clears it, the face opens
        // and the target moves back until no face lands it deeper: the
        // face is the deepest that landed the estimate, and that ball
        // clears the net.
        assert!(sure.converged && over_net(&sure, &more) < 0.0, "{sure:?}");
        assert!(over_net(&unsure, &more) > 0.0, "{unsure:?}");
        assert!(unsure.tilt > sure.tilt && unsure.target[0] < sure.target[0], "{sure:?} {unsure:?}");
        let l = unsure.landing;
        assert!(l.x < sure.landing.x - 0.2 && l.x > -prop.table.length / 2.0 && l.over_net >= NET_CLEARANCE, "{l:?}");
        // Topspin: more spin lifts the return; the target stays.
        let top = balls()[0];
        let a = aim(&bounds, target, &prop, &racket, &top, sigma, tilt0(&top), None, 64);
        assert!(a.converged && a.target == target, "{a:?}");
    }

    #[test]
    fn a_refinement_starts_from_the_last_aim() {
        let (bounds, target, prop, racket) = cell();
        let b = balls()[0];
        let first = aim(&bounds, target, &prop, &racket, &b, 0.0, tilt0(&b), None, 64);
        let mut moved = b;
        moved.pos.z += 0.01;
        moved.vel.x += 0.05;
        let again = aim(&bounds, target, &prop, &racket, &moved, 0.0, tilt0(&moved), Some(&first), AIM_BUDGET);
        assert!(again.converged);
        assert!((again.tilt - first.tilt).abs() < 0.05);
        assert_eq!(again.speed_step, first.speed_step);
    }

    #[test]
    fn a_fresh_search_takes_over_from_one_that_climbed_for_another_ball() {
        let (bounds, target, prop, racket) = cell();
        // Heavy backspin, slow and low: the search climbs to the fastest
        // bat (the same ball as the test below).
        let heavy = BallState::new(Vec3::new(1.6, 0.0, 0.16), Vec3::new(2.0, 0.0, -1.0), Vec3::new(0.0, -900.0, 0.0));
        let mut searches = Searches::default();
        for _ in 0..40 {
            searches.step(&bounds, target, &prop, &racket, &heavy, 0.0, tilt0(&heavy), AIM_BUDGET);
        }
        let climbed = searches.current.expect("aimed");
        assert_eq!(climbed.level + 1, SPEED_STEPS, "{climbed:?}");
        // The prediction moves to a ball a slower bat lands.
        let b = balls()[0];
        let cold = aim(&bounds, target, &prop, &racket, &b, 0.0, tilt0(&b), None, 64);
        assert!(cold.converged && cold.speed_step + 1 < SPEED_STEPS, "{cold:?}");
        let (mut alone, mut both) = (climbed, climbed);
        for _ in 0..20 {
            alone = aim(&bounds, target, &prop, &racket, &b, 0.0, tilt0(&b), Some(&alone), AIM_BUDGET);
            both = searches.step(&bounds, target, &prop, &racket, &b, 0.0, tilt0(&b), AIM_BUDGET);
        }
        // The search alone stays at the bat it climbed to; beside a fresh
        // one, the plan gets the slower bat's face, within each plan's
        // budget twice over.
        assert!(alone.speed_step > cold.speed_step, "{alone:?}");
        assert!(both.converged && both.speed_step == cold.speed_step, "{both:?}");
        assert!(
            (both.tilt - cold.tilt).abs() < 0.02,
            "{:.1}° vs {:.1}°",
            both.tilt.to_degrees(),
            cold.tilt.to_degrees()
        );
        assert!(both.flights <= 2 * AIM_BUDGET);
    }

    #[test]
    fn a_search_stuck_against_a_bound_starts_again_when_the_ball_moves() {
        let (bounds, target, prop, racket) = cell();
        // Heavy backspin, slow and low: the search ends against the open
        // bound at the fastest bat, without landing it.
        let heavy = BallState::new(Vec3::new(1.6, 0.0, 0.16), Vec3::new(2.0, 0.0, -1.0), Vec3::new(0.0, -900.0, 0.0));
        let stuck = aim(&bounds, target, &prop, &racket, &heavy, 0.0, tilt0(&heavy), None, 64);
        assert!(!stuck.converged && stuck.level + 1 == SPEED_STEPS, "{stuck:?}");
        // The prediction moves to a ball the start face lands: the search
        // leaves the bound and lands it, not the face found for the other.
        let b = balls()[3];
        let again = aim(&bounds, target, &prop, &racket, &b, 0.0, tilt0(&b), Some(&stuck), 64);
        assert!(again.converged, "{again:?}");
    }

    #[test]
    fn every_kind_of_return_lands_within_a_centimetre_of_the_propagators() {
        let (_, _, prop, _) = cell();
        let (mut worst, mut compared) = (0.0f64, 0);
        for vx in [-3.0, -4.5, -6.0, -7.5, -9.0] {
            for vz in [-0.5, 0.5, 1.5, 2.5] {
                for spin in [
                    Vec3::zeros(),
                    Vec3::new(0.0, -300.0, 0.0),
                    Vec3::new(0.0, 300.0, 0.0),
                    Vec3::new(0.0, -150.0, 150.0),
                    Vec3::new(100.0, 100.0, -200.0),
                ] {
                    let s = BallState::new(Vec3::new(1.55, 0.3, 0.25), Vec3::new(vx, -0.4, vz), spin);
                    let Some(l) = fly(&prop, &s) else { continue };
                    let (mut e, mut t) = (s, 0.0);
                    let ev = prop.advance(&mut e, &mut t, &StopAt { t_max: AIM_T_MAX, hit_plane_x: None, net: false });
                    let Event::Bounce { before, .. } = ev else { continue };
                    worst = worst.max((l.x - before.pos.x).hypot(l.y - before.pos.y));
                    compared += 1;
                }
            }
        }
        assert!(compared >= 80 && worst < 0.01, "{compared} returns, worst {worst} m");
    }

    #[test]
    fn returns_flown_together_land_where_each_lands_alone() {
        let (_, _, prop, _) = cell();
        let s = BallState::new(Vec3::new(1.6, 0.1, 0.3), Vec3::new(-6.5, -0.3, 1.5), Vec3::new(0.0, -150.0, 40.0));
        // A slower one lands first; a lob is still up at AIM_T_MAX; one
        // is no return at all.
        let short = BallState { vel: Vec3::new(-3.0, 0.0, 0.5), ..s };
        let lob = BallState { vel: Vec3::new(-2.0, 0.0, 9.0), ..s };
        let together = fly_all(&prop, [Some(s), Some(short), Some(lob), None]);
        assert_eq!(together, [fly(&prop, &s), fly(&prop, &short), fly(&prop, &lob), None]);
        assert!(together[1].unwrap().x > together[0].unwrap().x, "{together:?}");
    }

    #[test]
    fn a_plan_flies_at_most_its_budget() {
        let (bounds, target, prop, racket) = cell();
        let mut warm = None;
        for b in balls() {
            for k in 0..6 {
                let mut s = b;
                s.spin *= 1.0 + 0.02 * k as f64;
                let a = aim(&bounds, target, &prop, &racket, &s, 0.0, tilt0(&s), warm.as_ref(), AIM_BUDGET);
                assert!(a.flights <= AIM_BUDGET, "{a:?}");
                warm = Some(a);
            }
            warm = None;
        }
    }

    #[test]
    fn the_aim_stays_within_its_bounds() {
        let (bounds, target, prop, racket) = cell();
        // Heavy backspin, slow and low: wants more than the bounds give.
        let b = BallState::new(Vec3::new(1.6, 0.0, 0.16), Vec3::new(2.0, 0.0, -1.0), Vec3::new(0.0, -900.0, 0.0));
        let a = aim(&bounds, target, &prop, &racket, &b, 0.0, tilt0(&b), None, 64);
        assert!(a.tilt >= bounds.tilt.0 && a.tilt <= bounds.tilt.1, "{a:?}");
        assert!(a.heading.abs() <= MAX_HEADING && a.speed <= bounds.speed.1, "{a:?}");
    }
}
