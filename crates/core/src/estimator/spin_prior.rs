//! The session's spin prior: the spin the table meets per unit
//! of the spin a flight shows.
//!
//! A real ball's lift saturates, so a flight read through the
//! calibration's lift curve cannot tell a fast spin from a medium one, and
//! balls differ in their lift by ±25 %. The table can: a topspin ball's
//! forward kick grows with its spin until the contact slides. Each bounce
//! that tells (its kick depends on the spin) is kept, in the bin of the
//! spin parameter its flight showed at the contact; each bin's scale is
//! the one that best explains the kicks it holds, found on a fixed grid
//! (×0.5–4) with every bounce's cost capped (a bad ball moves it little).
//! Where the kicks only bound the scale from below (the contacts slid,
//! and every larger scale explains them as well), the bin takes the
//! middle of what fits: a kick cannot exceed the sliding one, so a scale
//! a little high costs little, and one too low makes the ball early.
//! A ball whose own spin was read, by the ceiling camera or from its
//! return ([`SpinPrior::take_read`]), tells its scale directly, with the
//! reading's own uncertainty: it is kept and weighed beside the bounces,
//! fast spins included (whose contacts slide). Each ball is also kept
//! with its speed and lift direction, once (its reading in the place of
//! what its bounce told): a launcher's spin, and a player's, grows with the
//! ball's speed, and where enough alike balls were read, their spin is
//! weighed against the bin's for the next ball ([`SpinPrior::ball_scale`]).
//! Fixed memory ([`BIN_MEMORY`] readings a bin, [`SPEED_MEMORY`] balls),
//! bounded work.

use crate::physics::{BallState, BounceModel, Vec3};

/// Bins of the spin scale.
pub const SPIN_BINS: usize = 4;
/// The bins' centres in the spin parameter S = r‖ω‖/‖v‖ the flight shows
/// at the contact; the scale is interpolated linearly between them.
pub const SPIN_BIN_CENTRES: [f64; SPIN_BINS] = [0.08, 0.2, 0.4, 0.8];
/// Bounces a bin keeps (the latest).
pub(crate) const BIN_MEMORY: usize = 16;
/// The grid of scales tried: ×0.5 to ×4 in steps of 2^(1/8).
const SCALE_GRID: usize = 25;
/// Most a bounce's normalised squared residual counts.
const COST_CAP: f64 = 16.0;
/// σ of ln(scale) about a bin's scale before it holds [`MIN_FOR_SHARE`]
/// readings: a flight's spin may be a third off (real balls, `docs/physics.md`).
pub(crate) const SHARE_START: f64 = 0.3;
/// σ of ln(spin) the aim allows a ball above its estimate, at the least
/// ([`SpinPrior::ball_scale`]): how far a flight alone may read a real
/// ball's spin low. Real balls' flights read 20–40 rev/s at 0.95 of the
/// truth but 40–80 at 0.53 and faster at 0.31 (`docs/physics.md`): from S
/// 0.4 up a flight may show half the spin or less, and balls differ in
/// their lift by ±25 %. A bin's readings tell its scale, not how far the
/// next ball's flight strays from it, and a backspin ball's bounce (it
/// slides) tells the bins nothing; only a reading of the ball's own spin
/// narrows it (alike balls of the speed memory, the camera). Only the aim
/// takes it (a return that clears the net with that much more spin); the
/// filter's spread at the contact stays the bin's, which costs timing
/// where the reading is right.
pub(crate) const FLIGHT_HEDGE: [f64; SPIN_BINS] = [SHARE_START, SHARE_START, 0.45, 0.6];
/// Readings (bounces and the camera's spins) a bin needs before its own
/// spread counts.
const MIN_FOR_SHARE: usize = 4;
/// Bounds of a bin's spread.
const SHARE_BOUNDS: (f64, f64) = (0.05, 0.6);
/// σ of ln(scale) of the prior that holds each bin at 1 (the
/// calibration's lift) until its bounces say otherwise.
const PRIOR_SIGMA: f64 = 0.5;
/// Least tangential spin at the contact (r‖ω_T‖, m/s) for the bounce to
/// tell anything about it.
const MIN_SURFACE_SPEED: f64 = 0.3;

/// The spin parameter S = r‖ω‖/‖v‖ of a state.
pub(crate) fn spin_parameter(state: &BallState, radius: f64) -> f64 {
    radius * state.spin.norm() / state.vel.norm().max(1e-9)
}

/// Balls whose own spin the prior keeps with their speed (the latest).
const SPEED_MEMORY: usize = 48;
/// Bounds of one ball's scale where alike balls weigh in: wider than the
/// bins' grid, since a saturated flight of a fast spin may show a sixth of
/// it (the spin it gives lies between the bins' and the alike balls').
const BALL_SCALE_BOUNDS: (f64, f64) = (0.25, 8.0);
/// Width of the kernel in ln(speed) over which balls count as alike.
const SPEED_KERNEL: f64 = 0.08;
/// Least summed kernel weight of alike balls for their spin to count: one
/// ball of the same speed. A launcher's setting repeats its spin within
/// [`SPEED_SHARE_FLOOR`], so one reading tells the next ball's; where
/// alike balls differ (a player's), their spread says so from the second.
const SPEED_MIN_WEIGHT: f64 = 1.0;
/// Least σ of ln(spin) of alike balls (a launcher's spin at one setting
/// strays by about this much).
const SPEED_SHARE_FLOOR: f64 = 0.08;

/// How far above its bound the speed memory keeps a ball whose bounce
/// slid ([`SpinPrior::take`]), in [`SPEED_SHARE_FLOOR`]s of ln(spin): two,
/// ×e^0.16 = ×1.17.
const SLID_ABOVE_BOUND_SPREADS: f64 = 2.0;

/// The factor of [`SLID_ABOVE_BOUND_SPREADS`].
fn slid_above_bound() -> f64 {
    (SLID_ABOVE_BOUND_SPREADS * SPEED_SHARE_FLOOR).exp()
}

/// Which way a ball's lift points: down (topspin), up (backspin) or
/// sideways; balls are alike only with the same.
fn lift_class(state: &BallState) -> i8 {
    let lift = state.spin.cross(&state.vel);
    let up = lift.z / lift.norm().max(1e-12);
    if up < -0.5 {
        1
    } else if up > 0.5 {
        -1
    } else {
        0
    }
}

/// One ball's own spin, as the prior keeps it with its speed.
#[derive(Copy, Clone, Debug, PartialEq)]
struct SpinSeen {
    ln_speed: f64,
    class: i8,
    ln_spin: f64,
    /// ln of the spin its flight showed at the contact, and the spin
    /// parameter there: what the bins would make of it.
    ln_flight: f64,
    s: f64,
    /// The ball's track: a ball is kept once, with its best reading.
    ball: u32,
    /// Its own spin was read (the camera, its return), not bounded or
    /// told by its bounce.
    read: bool,
}

fn grid(k: usize) -> f64 {
    0.5 * 2f64.powf(k as f64 / 8.0)
}

/// One reading a bin keeps.
#[derive(Copy, Clone, Debug, PartialEq)]
enum Seen {
    /// A bounce: the state at the contact as the flight showed it, the
    /// velocity seen just after it, and that velocity's variance.
    Bounce { before: BallState, after: Vec3, var: Vec3 },
    /// A ball whose own spin was read (the ceiling camera, its return):
    /// its scale, as ln, and that reading's σ.
    Read { ln_scale: f64, sigma: f64 },
}

impl Seen {
    /// Normalised squared residual of scale `m`: of the tangential
    /// velocity after the bounce under `table`, or of the logo's scale.
    fn cost(&self, table: &BounceModel, m: f64) -> f64 {
        match self {
            Seen::Bounce { before, after, var } => {
                let v = table.with_spin_scale(m).apply(before).vel;
                (0..2).map(|k| (v[k] - after[k]).powi(2) / var[k].max(1e-6)).sum()
            }
            Seen::Read { ln_scale, sigma } => ((m.ln() - ln_scale) / sigma).powi(2),
        }
    }

    fn costs(&self, table: &BounceModel) -> [f64; SCALE_GRID] {
        std::array::from_fn(|k| self.cost(table, grid(k)))
    }
}

/// The scale on the grid that best explains one bounce (`before` the state
/// at the contact as the flight showed it, `after` the velocity seen just
/// after it with per-axis variance `var`) under `table`: what a bounce
/// that surprised the filter is checked against, the spin's size being
/// what its flight could not tell.
pub(crate) fn best_scale(before: &BallState, after: &Vec3, var: &Vec3, table: &BounceModel) -> f64 {
    let costs = Seen::Bounce { before: *before, after: *after, var: *var }.costs(&table.with_spin_scale(1.0));
    let best = (0..SCALE_GRID).min_by(|&a, &b| costs[a].total_cmp(&costs[b])).unwrap_or(0);
    grid(best)
}

/// The grid indices whose cost lies within 1 of the least: the scales
/// the costs cannot tell apart.
fn fitting(costs: &[f64; SCALE_GRID]) -> (usize, usize) {
    let best = costs.iter().copied().fold(f64::INFINITY, f64::min);
    let lo = (0..SCALE_GRID).find(|&k| costs[k] <= best + 1.0).unwrap_or(0);
    let hi = (0..SCALE_GRID).rev().find(|&k| costs[k] <= best + 1.0).unwrap_or(SCALE_GRID - 1);
    (lo, hi)
}

/// What fits reaches the grid's top (`hi` of [`fitting`]): the spin is
/// bounded from below only (a topspin bounce that slid).
fn bounded_below_only(hi: usize) -> bool {
    hi == SCALE_GRID - 1
}

/// One ball's own scale from what fits it ([`fitting`]): the middle, or
/// where only bounded from below, no less than its bound and `bin` (the
/// scale of its bin).
fn own_scale((lo, hi): (usize, usize), bin: f64) -> f64 {
    if bounded_below_only(hi) { grid(lo).max(bin) } else { (grid(lo) * grid(hi)).sqrt() }
}

#[derive(Copy, Clone, Debug, PartialEq)]
struct Bin {
    seen: [Option<Seen>; BIN_MEMORY],
    next: usize,
    scale: f64,
    /// σ of ln(scale) of one ball about `scale`.
    share: f64,
}

impl Bin {
    /// Whether `share` is the bin's own (it holds [`MIN_FOR_SHARE`]
    /// readings), not the start's.
    fn has_own_share(&self) -> bool {
        self.seen.iter().flatten().count() >= MIN_FOR_SHARE
    }
}

/// The spin of the balls alike to one (their speed and lift direction),
/// in ln(spin): their mean and its σ for the next ball, and how far the
/// bins' scale times each one's flight spin missed its spin (RMS).
struct Alike {
    mean: f64,
    spread: f64,
    bin_miss: f64,
}

/// One ball's spin scale from the session ([`SpinPrior::ball_scale`]).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BallScale {
    /// The spin the table meets per unit of the flight's.
    pub scale: f64,
    /// σ of ln(scale) the filter adds at the contact.
    pub share: f64,
    /// σ of ln(spin) the aim allows above the estimate.
    pub hedge: f64,
}

/// The spin scale per bin of the flight's spin parameter.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SpinPrior {
    bins: [Bin; SPIN_BINS],
    /// Each ball's own spin as its bounce or the camera read it, with its
    /// speed and lift direction: how much spin comes with a speed.
    by_speed: [Option<SpinSeen>; SPEED_MEMORY],
    by_speed_next: usize,
    /// Bounces and logo readings taken in (that told something about the
    /// spin).
    pub count: u32,
}

impl Default for SpinPrior {
    fn default() -> Self {
        let bin = Bin { seen: [None; BIN_MEMORY], next: 0, scale: 1.0, share: SHARE_START };
        SpinPrior { bins: [bin; SPIN_BINS], by_speed: [None; SPEED_MEMORY], by_speed_next: 0, count: 0 }
    }
}

impl SpinPrior {
    /// Each bin's scale.
    pub fn scales(&self) -> [f64; SPIN_BINS] {
        self.bins.map(|b| b.scale)
    }

    /// How many balls' own spin is kept with their speed (at most
    /// `SPEED_MEMORY`).
    pub fn kept_by_speed(&self) -> usize {
        self.by_speed.iter().flatten().count()
    }

    /// What the speed memory keeps: each ball's track, spin (rad/s) and
    /// whether it was read (not told by its bounce).
    #[cfg(test)]
    pub(crate) fn remembered(&self) -> Vec<(u32, f64, bool)> {
        self.by_speed.iter().flatten().map(|s| (s.ball, s.ln_spin.exp(), s.read)).collect()
    }

    /// Each bin's spread: σ of ln(scale) of one ball about the bin's.
    pub fn shares(&self) -> [f64; SPIN_BINS] {
        self.bins.map(|b| b.share)
    }

    /// The scale for a flight showing spin parameter `s`: linear between
    /// the bins' centres, the end bins' values beyond them.
    pub fn scale_at(&self, s: f64) -> f64 {
        self.interpolate(s, |_, b| b.scale)
    }

    /// How far one ball's scale strays from [`Self::scale_at`], as σ of
    /// its logarithm (the filter's [`super::ekf::EkfNoise::bounce_spin_share`]).
    pub fn share_at(&self, s: f64) -> f64 {
        self.interpolate(s, |_, b| b.share)
    }

    /// How far the aim allows one ball's spin above its bin's scale, as σ
    /// of ln: the bin's spread, at least `FLIGHT_HEDGE`.
    pub fn hedge_at(&self, s: f64) -> f64 {
        self.interpolate(s, |k, b| b.share.max(FLIGHT_HEDGE[k]))
    }

    /// The scale for one ball as its flight shows it (`speed`: its speed
    /// at the net, the same point of every flight), the spread of its ln
    /// that the filter adds at the contact ([`Self::scale_at`],
    /// [`Self::share_at`]), and the one the aim allows for
    /// ([`Self::hedge_at`]): the bin's, weighed against the spin that
    /// balls of that speed and its lift direction came with, where enough
    /// such balls were read. A launcher's spin
    /// grows with its speed, as a player's does; where the lift
    /// saturates, a ball's speed tells its spin better than its flight.
    pub fn ball_scale(&self, state: &BallState, radius: f64, speed: f64) -> BallScale {
        let s = spin_parameter(state, radius);
        let bin = BallScale { scale: self.scale_at(s), share: self.share_at(s), hedge: self.hedge_at(s) };
        let w = state.spin.norm();
        if !(w > 0.0 && w.is_finite()) {
            return bin;
        }
        let Some(alike) = self.spin_by_speed(state, speed) else { return bin };
        // Inverse-variance weighting in ln(spin). The bin's spread is of
        // the scale its bounces need; how far its scale times a flight's
        // spin strays from the spin the alike balls had counts as well
        // (where the lift saturates, flights of one spin show a third of
        // it to nearly all).
        let bin_share = bin.share.max(alike.bin_miss);
        let (a, b) = (1.0 / (bin_share * bin_share), 1.0 / (alike.spread * alike.spread));
        let ln_w = ((w * bin.scale).ln() * a + alike.mean * b) / (a + b);
        let scale = (ln_w.exp() / w).clamp(BALL_SCALE_BOUNDS.0, BALL_SCALE_BOUNDS.1);
        let hedge = (1.0 / (bin.hedge.powi(-2) + b)).sqrt();
        BallScale { scale, share: (1.0 / (a + b)).sqrt(), hedge }
    }

    /// The balls of `state`'s speed and lift direction, kernel-weighted
    /// in ln(speed); `None` with too few.
    fn spin_by_speed(&self, state: &BallState, speed: f64) -> Option<Alike> {
        let (ln_v, class) = (speed.ln(), lift_class(state));
        let (mut sw, mut sx, mut sxx, mut smiss) = (0.0, 0.0, 0.0, 0.0);
        for seen in self.by_speed.iter().flatten().filter(|b| b.class == class) {
            let w = (-0.5 * ((seen.ln_speed - ln_v) / SPEED_KERNEL).powi(2)).exp();
            sw += w;
            sx += w * seen.ln_spin;
            sxx += w * seen.ln_spin * seen.ln_spin;
            smiss += w * (seen.ln_flight + self.scale_at(seen.s).ln() - seen.ln_spin).powi(2);
        }
        if sw.is_nan() || sw < SPEED_MIN_WEIGHT {
            return None;
        }
        let mean = sx / sw;
        let var = (sxx / sw - mean * mean).max(SPEED_SHARE_FLOOR * SPEED_SHARE_FLOOR);
        // The spread of alike balls, and the mean's own uncertainty.
        Some(Alike { mean, spread: (var * (1.0 + 1.0 / sw)).sqrt(), bin_miss: (smiss / sw).sqrt() })
    }

    /// Keeps `ball`'s spin with its speed `v` (`read`: its own spin was
    /// read), in the place of what it kept of that ball before unless
    /// that was read and this is not.
    fn remember_spin(&mut self, flight: &BallState, s: f64, scale: f64, v: f64, ball: u32, read: bool) {
        let w = flight.spin.norm() * scale;
        if !(w > 0.0 && w.is_finite() && v > 0.0 && v.is_finite() && s.is_finite()) {
            return;
        }
        let ln_flight = flight.spin.norm().ln();
        let seen = SpinSeen { ln_speed: v.ln(), class: lift_class(flight), ln_spin: w.ln(), ln_flight, s, ball, read };
        match self.by_speed.iter().position(|s| s.is_some_and(|s| s.ball == ball)) {
            Some(k) if self.by_speed[k].is_some_and(|s| s.read && !read) => {}
            Some(k) => self.by_speed[k] = Some(seen),
            None => {
                self.by_speed[self.by_speed_next] = Some(seen);
                self.by_speed_next = (self.by_speed_next + 1) % SPEED_MEMORY;
            }
        }
    }

    fn interpolate(&self, s: f64, of: impl Fn(usize, &Bin) -> f64) -> f64 {
        let c = &SPIN_BIN_CENTRES;
        let v = |k: usize| of(k, &self.bins[k]);
        if s.is_nan() || s <= c[0] {
            return v(0);
        }
        for k in 1..SPIN_BINS {
            if s <= c[k] {
                let f = (s - c[k - 1]) / (c[k] - c[k - 1]);
                return v(k - 1) + f * (v(k) - v(k - 1));
            }
        }
        v(SPIN_BINS - 1)
    }

    /// Takes one bounce: `before` the state at the contact as the flight
    /// showed it, `after` the velocity seen just after it with per-axis
    /// variance `var` (of the reading and of what the table leaves
    /// unexplained), `table` the session's table. Kept in the bin nearest
    /// to the flight's spin parameter where the kick depends on the spin
    /// (true), and that bin's scale found anew. `var` holds the flight's
    /// own uncertainty through the contact (not the bin's spread), so that
    /// what fits one kick is what the reading and the tracker leave open.
    /// `speed`: the ball's at the net ([`Self::ball_scale`]).
    pub fn take(
        &mut self,
        before: &BallState,
        after: &Vec3,
        var: &Vec3,
        table: &BounceModel,
        speed: f64,
        ball: u32,
    ) -> bool {
        let seen = Seen::Bounce { before: *before, after: *after, var: *var };
        let table = table.with_spin_scale(1.0);
        if table.radius * before.spin.x.hypot(before.spin.y) < MIN_SURFACE_SPEED {
            return false;
        }
        // Every scale down to the grid's least fits: the kick does not
        // depend on the spin (a backspin ball slides whatever it has).
        let costs = seen.costs(&table);
        let (lo, hi) = fitting(&costs);
        if lo == 0 {
            return false;
        }
        let s = spin_parameter(before, table.radius);
        let bin = self.scale_at(s);
        // A bounce that slid bounds the spin from below. Kept at its bound,
        // the next alike ball, whose spin strays by about
        // SPEED_SHARE_FLOOR, would be predicted where half of them no longer
        // slide: its kick too small, its plan late. Two of that spread above.
        let remembered =
            if bounded_below_only(hi) { (grid(lo) * slid_above_bound()).max(bin) } else { own_scale((lo, hi), bin) };
        self.keep(seen, s, &table);
        self.remember_spin(before, s, remembered, speed, ball, false);
        true
    }

    /// Takes one ball whose own spin was read, by the ceiling camera or from
    /// its return (`estimator::returns`): `flight` its state as the flight
    /// showed it, `scale` the spin read per unit of the flight's (its σ in
    /// ln: `sigma`), `table` the table the bin's kept bounces are costed
    /// against when its scale is found anew (the estimator passes the
    /// calibration's here, the session's with a bounce: passing the
    /// session's here too was measured and not kept). Kept in the bin of
    /// the flight's spin parameter, as a bounce is, and with `speed` as
    /// [`Self::take`] keeps it, in the place of what the ball's bounce
    /// told; false (nothing kept) for a scale off the grid or not finite.
    pub fn take_read(
        &mut self,
        flight: &BallState,
        scale: f64,
        sigma: f64,
        table: &BounceModel,
        speed: f64,
        ball: u32,
    ) -> bool {
        let usable = scale.is_finite() && sigma.is_finite() && sigma > 0.0;
        if !(usable && (grid(0)..=grid(SCALE_GRID - 1)).contains(&scale)) {
            return false;
        }
        let table = table.with_spin_scale(1.0);
        let s = spin_parameter(flight, table.radius);
        self.keep(Seen::Read { ln_scale: scale.ln(), sigma }, s, &table);
        self.remember_spin(flight, s, scale, speed, ball, true);
        true
    }

    /// Keeps `seen` in the bin nearest spin parameter `s` and finds that
    /// bin's scale and spread anew.
    fn keep(&mut self, seen: Seen, s: f64, table: &BounceModel) {
        let c = &SPIN_BIN_CENTRES;
        let k = (0..SPIN_BINS).min_by(|&a, &b| (c[a] - s).abs().total_cmp(&(c[b] - s).abs())).expect("bins");
        let bin = &mut self.bins[k];
        bin.seen[bin.next] = Some(seen);
        bin.next = (bin.next + 1) % BIN_MEMORY;
        // Each kept bounce's costs, once.
        let costs: [Option<[f64; SCALE_GRID]>; BIN_MEMORY] = bin.seen.map(|seen| seen.map(|s| s.costs(table)));
        let mut total: [f64; SCALE_GRID] = std::array::from_fn(|k| (grid(k).ln() / PRIOR_SIGMA).powi(2));
        for c in costs.iter().flatten() {
            for (t, c) in total.iter_mut().zip(c) {
                *t += c.min(COST_CAP);
            }
        }
        let (lo, hi) = fitting(&total);
        bin.scale = (grid(lo) * grid(hi)).sqrt();
        // Each ball's own scale (where only bounded below, no less than
        // its bound) about the bin's, less what its kick leaves open (the
        // half-width of what fits it, ±1σ: the flight's reading and the
        // tracker's noise, not the ball).
        let (mut sum, mut n) = (0.0, 0usize);
        for c in costs.iter().flatten() {
            let (lo, hi) = fitting(c);
            let own = own_scale((lo, hi), bin.scale);
            sum += if bounded_below_only(hi) {
                // Bounded from below only: it tells nothing of how far a
                // ball strays above the bin (the start's spread).
                (own / bin.scale).ln().powi(2).max(SHARE_START * SHARE_START)
            } else {
                let open = 0.5 * (grid(hi) / grid(lo)).ln();
                (own / bin.scale).ln().powi(2) - open * open
            };
            n += 1;
        }
        if bin.has_own_share() {
            bin.share = (sum / n as f64).max(0.0).sqrt().clamp(SHARE_BOUNDS.0, SHARE_BOUNDS.1);
        }
        self.count = self.count.saturating_add(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const R: f64 = 0.02;

    fn shown(w: f64) -> BallState {
        BallState::new(Vec3::zeros(), Vec3::new(5.0, 0.0, -3.0), Vec3::new(0.0, w, 0.0))
    }

    /// Topspin balls whose flights showed half their spin (they roll off
    /// the table): the bin learns ×2; a backspin ball teaches nothing (it
    /// slides whatever its spin); the other bins stay at 1.
    #[test]
    fn the_bounce_reads_the_spin_the_flight_could_not() {
        let table = BounceModel::new(0.92, 0.2, R);
        let var = Vec3::repeat(0.03f64.powi(2));
        let mut prior = SpinPrior::default();
        for k in 0..20 {
            let truth = 200.0 + k as f64;
            assert!(prior.take(&shown(0.5 * truth), &table.apply(&shown(truth)).vel, &var, &table, 5.83, k));
        }
        // S shown: 0.02·105/5.83 = 0.36, the bin at 0.4.
        let s = prior.scales();
        assert!((s[2] - 2.0).abs() < 0.1, "{s:?}");
        // Balls alike: their spread is the least; the others' the start.
        let shares = prior.shares();
        assert!(shares[2] < 0.1 && [shares[0], shares[1], shares[3]] == [SHARE_START; 3], "{shares:?}");
        assert_eq!((s[0], s[1], s[3]), (1.0, 1.0, 1.0));
        assert!(!prior.take(&shown(-150.0), &table.apply(&shown(-300.0)).vel, &var, &table, 5.83, 102));
        assert_eq!(prior.count, 20);
        assert!((prior.scale_at(0.3) - (1.0 + 0.5 * (s[2] - 1.0))).abs() < 1e-9);
        assert_eq!(prior.scale_at(5.0), 1.0);
    }

    /// The camera read topspin balls at 8 m/s at 600 rad/s whose flights
    /// showed 300: a new ball of that speed and lift whose flight shows
    /// 250 is taken at close to 600, more surely than its bin alone says;
    /// a ball as fast with backspin, or a slower one, keeps its bin's.
    #[test]
    fn a_balls_speed_tells_its_spin() {
        let table = BounceModel::new(0.92, 0.2, R);
        let at = |v: f64, w: f64| BallState::new(Vec3::zeros(), Vec3::new(v, 0.0, -2.0), Vec3::new(0.0, w, 0.0));
        let mut prior = SpinPrior::default();
        let before = prior.ball_scale(&at(8.0, 250.0), R, 8.0);
        for k in 0..6 {
            let v = 8.0 + 0.05 * k as f64;
            assert!(prior.take_read(&at(v, 300.0), 2.0, 0.05, &table, v, k));
        }
        assert_eq!(prior.kept_by_speed(), 6);
        let BallScale { scale: k, share, hedge } = prior.ball_scale(&at(8.0, 250.0), R, 8.0);
        let s = spin_parameter(&at(8.0, 250.0), R);
        let (bin_k, bin_share) = (prior.scale_at(s), prior.share_at(s));
        assert!((250.0 * k - 600.0).abs() < 0.1 * 600.0 && share < bin_share, "×{k} σ {share}; bin ×{bin_k}");
        assert!(hedge < prior.hedge_at(s), "{hedge}");
        assert_eq!(before.scale, 1.0);
        let back = at(8.0, -250.0);
        assert_eq!(prior.ball_scale(&back, R, 8.0).scale, prior.scale_at(spin_parameter(&back, R)));
        let slow = at(5.0, 250.0);
        assert_eq!(prior.ball_scale(&slow, R, 5.0).scale, prior.scale_at(spin_parameter(&slow, R)));
    }

    /// One ball the camera read at 8 m/s tells the next ball of that speed
    /// and lift its spin, with the floor's spread and the mean's own
    /// uncertainty (σ 0.08·√2); a ball 13 % slower is not alike.
    #[test]
    fn one_alike_ball_tells_the_next_ones_spin() {
        let table = BounceModel::new(0.92, 0.2, R);
        let at = |v: f64, w: f64| BallState::new(Vec3::zeros(), Vec3::new(v, 0.0, -2.0), Vec3::new(0.0, w, 0.0));
        let mut prior = SpinPrior::default();
        assert!(prior.take_read(&at(8.0, 300.0), 2.0, 0.05, &table, 8.0, 104));
        let next = at(8.0, 250.0);
        let s = spin_parameter(&next, R);
        let (bin_k, bin_share) = (prior.scale_at(s), prior.share_at(s));
        let BallScale { scale: k, share, .. } = prior.ball_scale(&next, R, 8.0);
        let memory = (2.0 * SPEED_SHARE_FLOOR * SPEED_SHARE_FLOOR).recip();
        let expected = (250.0 * bin_k).ln() * bin_share.powi(-2) + 600f64.ln() * memory;
        let expected = (expected / (bin_share.powi(-2) + memory)).exp();
        assert!((250.0 * k - expected).abs() < 1e-6 * expected, "{} vs {expected}", 250.0 * k);
        assert!((share - (bin_share.powi(-2) + memory).sqrt().recip()).abs() < 1e-12, "{share}");
        assert!((250.0 * k - 600.0).abs() < 0.15 * 600.0, "×{k}");
        let slower = at(7.0, 250.0);
        assert_eq!(prior.ball_scale(&slower, R, 7.0).scale, prior.scale_at(spin_parameter(&slower, R)));
    }

    /// The aim allows fast spin nearly twice the flight's reading (real
    /// balls' flights read it at 0.3–0.5), slow spin a third more, however
    /// many readings agree on the bin's scale; a bin whose balls stray
    /// further, its own spread.
    #[test]
    fn the_aim_hedges_what_a_flight_may_hide_whatever_the_bins_hold() {
        let table = BounceModel::new(0.92, 0.2, R);
        let mut prior = SpinPrior::default();
        assert_eq!([prior.hedge_at(0.05), prior.hedge_at(0.8), prior.hedge_at(2.0)], [SHARE_START, 0.6, 0.6]);
        assert!((prior.hedge_at(0.6) - 0.525).abs() < 1e-12);
        assert_eq!(prior.shares(), [SHARE_START; SPIN_BINS]);
        let at = |w: f64| BallState::new(Vec3::zeros(), Vec3::new(6.0, 0.0, -2.0), Vec3::new(0.0, w, 0.0));
        assert!((spin_parameter(&at(240.0), R) - 0.76).abs() < 0.01);
        for k in 0..MIN_FOR_SHARE {
            assert!(prior.take_read(&at(240.0), 2.0 + 0.01 * k as f64, 0.05, &table, 6.0, k as u32));
        }
        let share = prior.shares()[3];
        assert!(share < 0.1, "{share}");
        assert_eq!(prior.hedge_at(0.8), FLIGHT_HEDGE[3]);
        // S 0.2: balls read at ×0.5 to ×4 of their flights.
        assert!((spin_parameter(&at(60.0), R) - 0.19).abs() < 0.01);
        for k in [0.5, 1.0, 2.0, 4.0] {
            assert!(prior.take_read(&at(60.0), k, 0.05, &table, 6.0 * k, (8.0 * k) as u32));
        }
        let wide = prior.shares()[1];
        assert!(wide > FLIGHT_HEDGE[1], "{wide}");
        assert_eq!(prior.hedge_at(0.2), wide);
    }

    /// Fast topspin that slides at the contact, shown at a third of its
    /// spin: the kick only bounds the scale from below; the bin's scale
    /// lies past that bound, and its kick is the ball's.
    #[test]
    fn a_sliding_contact_bounds_the_scale_from_below() {
        let table = BounceModel::new(0.92, 0.2, R);
        let var = Vec3::repeat(0.03f64.powi(2));
        let mut prior = SpinPrior::default();
        let after = table.apply(&shown(600.0)).vel;
        for k in 0..8 {
            prior.take(&shown(200.0), &after, &var, &table, 5.83, k);
        }
        // S shown 0.69: kept in the bin at 0.8.
        let m = prior.scales()[3];
        let kick = table.with_spin_scale(m).apply(&shown(200.0)).vel.x;
        assert!((kick - after.x).abs() < 0.02 && m <= 4.0, "×{m}: {kick} vs {}", after.x);
    }

    /// A bounce that slid is remembered two spreads of alike balls above
    /// its bound: the next alike ball, shown as little spin but coming
    /// down 20 % steeper (it needs more spin to slide), is predicted to
    /// slide as the first did, its kick the true one. Kept at the bound
    /// itself, it was predicted to grip, its kick 0.25 m/s short.
    #[test]
    fn a_slid_bounce_is_remembered_above_its_bound() {
        let table = BounceModel::new(0.92, 0.2, R);
        let var = Vec3::repeat(0.03f64.powi(2));
        let mut prior = SpinPrior::default();
        let after = table.apply(&shown(600.0)).vel;
        let costs = Seen::Bounce { before: shown(200.0), after, var }.costs(&table);
        let (lo, hi) = fitting(&costs);
        assert!(bounded_below_only(hi), "only bounded from below");
        assert!(prior.take(&shown(200.0), &after, &var, &table, 5.83, 108));
        let mean = prior.spin_by_speed(&shown(200.0), 5.83).expect("one alike ball").mean;
        let bound = 200.0 * grid(lo);
        assert!((mean.exp() - bound * slid_above_bound()).abs() < 1e-9 * bound, "{} vs {bound}", mean.exp());
        let steeper = |w: f64| BallState::new(Vec3::zeros(), Vec3::new(5.0, 0.0, -3.6), Vec3::new(0.0, w, 0.0));
        let next = prior.ball_scale(&steeper(200.0), R, 5.83);
        let kick = table.with_spin_scale(next.scale).apply(&steeper(200.0)).vel.x;
        let truth = table.apply(&steeper(600.0)).vel.x;
        assert!((kick - truth).abs() < 0.02, "×{}: {kick} vs {truth}", next.scale);
    }

    /// Balls of one speed and spin whose saturated flights showed it
    /// ×0.25–0.6 (real balls' lift differs by ±25 %, and past S 0.5 it
    /// barely grows), in bins that balls of another speed taught ×2 with
    /// little spread: the bins' scale times a flight's spin misses the
    /// alike balls' spin by far more than the bins' spread, so the next
    /// alike ball takes their spin. Weighed by the bins' spread alone, it
    /// was given 0.6 of it.
    #[test]
    fn alike_balls_outweigh_bins_that_miss_them() {
        let table = BounceModel::new(0.92, 0.2, R);
        let mut prior = SpinPrior::default();
        let shown_as = [150.0, 350.0, 200.0, 300.0, 250.0, 180.0, 320.0, 220.0];
        for (k, w) in shown_as.iter().enumerate() {
            assert!(prior.take_read(&shown(*w), 600.0 / w, 0.05, &table, 5.83, k as u32));
        }
        // Shown at S 0.51 (the bin at 0.4) and 1.03 (at 0.8): each bin
        // holds only these.
        for k in 0..2 * BIN_MEMORY {
            let w = [150.0, 300.0][k % 2];
            assert!(prior.take_read(&shown(w), 2.0, 0.05, &table, 3.0, 100 + k as u32));
        }
        assert!(prior.shares()[2..].iter().all(|s| *s < 0.1), "{:?}", prior.shares());
        for w in [150.0, 240.0, 350.0] {
            let spin = prior.ball_scale(&shown(w), R, 5.83).scale * w;
            assert!((spin / 600.0 - 1.0).abs() < 0.1, "shown {w}: {spin:.0} rad/s, the balls' 600");
        }
    }

    /// One wild bounce among many good ones moves the bin's scale little.
    #[test]
    fn a_bad_bounce_moves_the_scale_little() {
        let table = BounceModel::new(0.92, 0.2, R);
        let var = Vec3::repeat(0.03f64.powi(2));
        let mut prior = SpinPrior::default();
        for k in 0..12 {
            let truth = 200.0 + k as f64;
            prior.take(&shown(0.5 * truth), &table.apply(&shown(truth)).vel, &var, &table, 5.83, k);
        }
        let good = prior.scales()[2];
        let wild = table.apply(&shown(200.0)).vel + Vec3::new(-1.5, 0.8, 0.0);
        prior.take(&shown(100.0), &wild, &var, &table, 5.83, 110);
        assert!((prior.scales()[2] - good).abs() < 0.1 * good, "{good} → {:?}", prior.scales());
    }

    /// The camera read each ball's spin at twice what its flight showed:
    /// the bin learns ×2 from the readings alone, fast spins included
    /// (whose contacts slide and teach the table nothing); a reading off
    /// the grid, or without a finite σ, is refused.
    #[test]
    fn the_logo_tells_the_scale_directly() {
        let table = BounceModel::new(0.92, 0.2, R);
        let mut prior = SpinPrior::default();
        for k in 0..8 {
            assert!(prior.take_read(&shown(250.0 + k as f64), 2.0, 0.05, &table, 5.83, k));
        }
        // S shown: 0.02·250/5.83 = 0.86, the bin at 0.8.
        let s = prior.scales();
        assert!((s[3] - 2.0).abs() < 0.1, "{s:?}");
        assert_eq!((s[0], s[1], s[2]), (1.0, 1.0, 1.0));
        assert!(prior.shares()[3] <= 0.1, "{:?}", prior.shares());
        assert_eq!(prior.count, 8);
        for (scale, sigma) in [(8.0, 0.05), (0.2, 0.05), (f64::NAN, 0.05), (2.0, 0.0), (2.0, f64::INFINITY)] {
            assert!(!prior.take_read(&shown(250.0), scale, sigma, &table, 5.83, 112), "{scale} {sigma}");
        }
        assert_eq!(prior.count, 8);
    }
}
