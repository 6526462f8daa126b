//! The pre-bounce flight re-read in one batch: the state at the window's
//! first sample, and the flight's drag, that explain every sample of it
//! through the flight model (Gauss–Newton), handed to the filter at the
//! window's last one.
//!
//! Why: the EKF linearises the flight at its running estimate, and where
//! the lift saturates (fast spin) the lift's slope in the spin is steeper
//! at a low estimate than at a high one. Noise that pulls the estimate low
//! is then taken as more informative than noise that pulls it high, and
//! the filter settles low: on the calibration's own flights with 2 mm
//! noise, fast topspin read at 0.86 of its true size (median), from any
//! start, while the batch fit over the same samples reads 1.0. The batch
//! linearises every sample at one estimate and re-linearises at the
//! answer, so the whole flight speaks at the same slope.
//!
//! The drag is read with the spin, as a multiplier of the flight the
//! filter flies (the session's air and the ball's own cubic reading),
//! with the calibration's spread of one flight's drag as its prior
//! (`physics.flight_variation.drag`): a heavy ball's slowing is not taken
//! for lift. The spin along the first velocity keeps the filter's prior
//! ([`super::EstimatorConfig::spin_prior_along_velocity`]) in information
//! form, so a flight that shows that component moves it; the spin's size
//! keeps the refined fit's weak prior ([`crate::fit::refine::SPIN_PRIOR_STD`]),
//! which a short window or a saturating lift would otherwise leave free.
//! The filter takes the spin and its covariance from the window (the
//! inverse of the normal equations with the priors, position, velocity and
//! drag marginalised); its position and velocity and their covariance stay
//! its own.
//!
//! Bounded, allocation-free and spread out: a [`Batch`] reads at most
//! [`super::WINDOW_CAP`] samples per pass and [`PASSES`] passes, and the
//! estimator advances it by at most [`SAMPLES_PER_STEP`] samples per
//! observation (one RK4 step and a few 3×10 products each), so no
//! observation pays for a whole pass. A pass that raises the residuals
//! halves the step from the best point; the best point is kept, and the
//! filter's own where no pass beats it.

use std::ops::{AddAssign, SubAssign};

use nalgebra::{Cholesky, Const, Matrix3, SMatrix, SVector};

use super::ekf::COV_STEP;
use crate::fit::Sample;
use crate::physics::{BallState, FlightScales, Propagator, Sensitivities, Vec3};

/// Linearisations at most: the filter's state, then Gauss–Newton steps
/// (from the filter's state two or three reach the answer; from far off,
/// five).
pub(crate) const PASSES: usize = 6;
/// Window samples a batch reads per observation at most (a spin read
/// late is a spin the filter drifts from meanwhile: at 16, a batch over
/// the window to the net ended 12 observations after it began).
pub(crate) const SAMPLES_PER_STEP: usize = 32;
/// A step shorter than this in position and velocity (m, m/s) …
const CONVERGED_STATE: f64 = 1e-3;
/// … in spin (rad/s) …
const CONVERGED_SPIN: f64 = 2.0;
/// … and in the drag's logarithm ends the search, the step taken: so
/// short a step is where the flight is linear in the unknowns.
const CONVERGED_DRAG: f64 = 3e-3;
/// The first batch reads a window of [`FIRST`] samples, or of as much
/// flight as that is at 150 Hz ([`FIRST_SPAN`]) where the tracker is
/// slower; the next one starts when the window has grown by [`EVERY`]
/// samples, or by [`EVERY_SPAN`] of flight. Never fewer than [`FIRST_MIN`]
/// and [`EVERY_MIN`] samples.
const FIRST: usize = 24;
/// See [`FIRST`], s (24 samples at 150 Hz span 153 ms).
const FIRST_SPAN: f64 = 0.15;
/// See [`FIRST`].
const FIRST_MIN: usize = 16;
/// See [`FIRST`].
const EVERY: usize = 8;
/// See [`FIRST`], s (8 samples at 150 Hz: 53 ms).
const EVERY_SPAN: f64 = 0.05;
/// See [`FIRST`].
const EVERY_MIN: usize = 4;

/// Whether a batch is due over `window`, the last having begun when it
/// held `from` samples (0: none yet). A slower tracker reads the spin after
/// as much flight as one at 150 Hz; a faster one as often in samples.
pub(crate) fn due(window: &[Sample], from: usize) -> bool {
    let n = window.len();
    if from == 0 {
        n >= FIRST || (n >= FIRST_MIN && window[n - 1].t - window[0].t >= FIRST_SPAN)
    } else {
        n >= from + EVERY || (n >= from + EVERY_MIN && window[n - 1].t - window[from - 1].t >= EVERY_SPAN)
    }
}

/// The unknowns: position, velocity and spin at the window's first
/// sample, and the natural logarithm of this flight's drag multiplier.
const N: usize = 10;
type VN = SVector<f64, N>;
type MN = SMatrix<f64, N, N>;
const DRAG: usize = 9;

/// What the window is read against besides its samples.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Priors {
    /// The tracker's per-axis noise, m.
    pub sigma: f64,
    /// σ of the spin along the window's first velocity, rad/s.
    pub along_std: f64,
    /// σ of each spin component about zero, rad/s: weak, it bounds the
    /// spin's size where the window cannot (a saturating lift, a short
    /// window: without it 24-sample windows at 380 Hz read 10⁵–10⁷ rad/s).
    pub spin_std: f64,
    /// σ of ln(drag multiplier) about the flight it is given (0: the
    /// drag is held).
    pub drag_std: f64,
}

/// The window read in one batch: the state at its last sample and this
/// flight's drag as a multiplier of the flight it was given.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Smoothed {
    pub state: BallState,
    pub drag: f64,
    /// Covariance of the spin from the window (position, velocity and
    /// drag marginalised), rad²/s²; `None` where the normal equations are
    /// singular.
    pub spin_cov: Option<Matrix3<f64>>,
}

fn state_of(x: &VN) -> BallState {
    BallState::new(Vec3::new(x[0], x[1], x[2]), Vec3::new(x[3], x[4], x[5]), Vec3::new(x[6], x[7], x[8]))
}

/// One linearisation at `x`, part way through the window: the flight so
/// far, the sensitivity of its position and velocity to the unknowns
/// ([`Sensitivities`]), and the normal equations.
#[derive(Copy, Clone, Debug)]
struct Pass {
    x: VN,
    /// The physics given, with this pass's drag.
    prop: Propagator,
    /// Next window sample, the flight's state and time there.
    cursor: usize,
    s: BallState,
    t: f64,
    phi: Sensitivities<N>,
    h: MN,
    g: VN,
    /// Σ‖residual‖²/σ² so far.
    cost: f64,
}

/// A finished pass: its cost with the priors' terms, the Gauss–Newton step
/// from its point and the state at the window's last sample.
#[derive(Copy, Clone, Debug)]
struct Finished {
    x: VN,
    cost: f64,
    step: Option<VN>,
    last: BallState,
    /// The normal equations with the priors (the inverse covariance),
    /// factored: the step's and the covariance's.
    chol: Option<Cholesky<f64, Const<N>>>,
}

impl Pass {
    fn new(prop: &Propagator, x: VN, t0: f64) -> Self {
        let phi = Sensitivities::new(Some(DRAG), None);
        let prop = Propagator { flight: prop.flight.scaled(FlightScales { drag: x[DRAG].exp(), lift: 1.0 }), ..*prop };
        Pass { x, prop, cursor: 0, s: state_of(&x), t: t0, phi, h: MN::zeros(), g: VN::zeros(), cost: 0.0 }
    }

    /// Reads the window's samples up to `end` (exclusive).
    fn run(&mut self, window: &[Sample], end: usize, w2: f64) {
        while self.cursor < end.min(window.len()) {
            let sample = window[self.cursor];
            self.cursor += 1;
            if sample.t > self.t {
                self.phi.fly(&self.prop, &mut self.s, sample.t - self.t, COV_STEP);
                self.t = sample.t;
            }
            let r = sample.pos - self.s.pos;
            let j = &self.phi.pos;
            // h += w2 jᵀj, g += w2 jᵀr, in place.
            self.h.gemm_tr(w2, j, j, 1.0);
            self.g.gemv_tr(w2, j, &r, 1.0);
            self.cost += r.norm_squared() * w2;
        }
    }

    /// Adds the priors and solves for the step (`None`: not finite).
    fn finish(mut self, priors: &Priors, along: &Vec3) -> Option<Finished> {
        let x = self.x;
        // The spin along the first velocity: ½ (a·ω)²/σ_a².
        let info = along * along.transpose() / (priors.along_std * priors.along_std);
        let spin = Vec3::new(x[6], x[7], x[8]);
        self.h.fixed_view_mut::<3, 3>(6, 6).add_assign(&info);
        self.g.fixed_rows_mut::<3>(6).sub_assign(&(info * spin));
        let mut cost = self.cost + along.dot(&spin).powi(2) / (priors.along_std * priors.along_std);
        // Its size about zero: ½ ‖ω‖²/σ_s².
        let size_info = 1.0 / (priors.spin_std * priors.spin_std);
        for k in 6..9 {
            self.h[(k, k)] += size_info;
        }
        self.g.fixed_rows_mut::<3>(6).sub_assign(&(spin * size_info));
        cost += spin.norm_squared() * size_info;
        // The drag about the flight given: ½ (ln m)²/σ_d² (held where σ_d = 0).
        let drag_info = if priors.drag_std > 0.0 { 1.0 / (priors.drag_std * priors.drag_std) } else { 1e12 };
        self.h[(DRAG, DRAG)] += drag_info;
        self.g[DRAG] -= drag_info * x[DRAG];
        cost += drag_info * x[DRAG] * x[DRAG];
        if !(cost.is_finite() && self.s.is_finite()) {
            return None;
        }
        let chol = self.h.cholesky();
        let step = chol.as_ref().map(|c| c.solve(&self.g)).filter(|d| d.iter().all(|v| v.is_finite()));
        Some(Finished { x, cost, step, last: self.s, chol })
    }
}

/// Where a [`Batch`] stands after [`Batch::advance`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) enum Progress {
    /// More to read.
    Running,
    /// Done: what it found, or `None` where nothing beat the filter.
    Done(Option<Smoothed>),
}

/// A batch read of a window's first `n` samples in progress.
#[derive(Copy, Clone, Debug)]
pub(crate) struct Batch {
    /// How many of the window's samples it reads.
    n: usize,
    /// The physics it reads against (the drag it finds multiplies this).
    pub prop: Propagator,
    priors: Priors,
    along: Vec3,
    /// The window's first sample time, s.
    t0: f64,
    passes: usize,
    pass: Pass,
    filter_cost: f64,
    /// The best point so far and the step from it; a step that raises the
    /// residuals is halved from there (a backtracking search).
    best: Option<(Finished, VN)>,
    shrink: f64,
}

impl Batch {
    /// Begins reading `window` (all of it) against `prop`, from the
    /// filter's state `last` at its last sample; `None` where the window
    /// is too short to say or the priors are not usable.
    pub(crate) fn start(prop: &Propagator, window: &[Sample], last: &BallState, priors: &Priors) -> Option<Batch> {
        let (first, end) = (window.first()?, window.last()?);
        if window.len() < super::ACQUIRE_LEN
            || !(priors.sigma > 0.0 && priors.along_std > 0.0 && priors.spin_std > 0.0 && priors.drag_std >= 0.0)
            || !last.is_finite()
        {
            return None;
        }
        // Back to the first sample along the filter's own flight, in the
        // passes' steps: only where the first pass starts, and the
        // observation that starts a batch is the estimator's slowest
        // (at the 4 ms propagator step the flight back cost it 3 µs of
        // its p99; the plans were the same to two decimals).
        let mut s = *last;
        let mut t = end.t;
        while t > first.t {
            let h = (first.t - t).max(-COV_STEP.max(prop.dt));
            s = prop.rk4(&s, h);
            t += h;
        }
        let along = s.vel.try_normalize(1e-9)?;
        let x = VN::from_iterator(s.pos.iter().chain(s.vel.iter()).chain(s.spin.iter()).copied().chain([0.0]));
        Some(Batch {
            n: window.len(),
            prop: *prop,
            priors: *priors,
            along,
            t0: first.t,
            passes: 0,
            pass: Pass::new(prop, x, first.t),
            filter_cost: f64::INFINITY,
            best: None,
            shrink: 1.0,
        })
    }

    /// Reads at most `budget` more samples of `window` (the same window it
    /// began with, grown or not).
    pub(crate) fn advance(&mut self, window: &[Sample], mut budget: usize) -> Progress {
        let w2 = 1.0 / (self.priors.sigma * self.priors.sigma);
        let window = &window[..self.n.min(window.len())];
        loop {
            let before = self.pass.cursor;
            self.pass.run(window, before.saturating_add(budget), w2);
            budget -= self.pass.cursor - before;
            if self.pass.cursor < window.len() {
                return Progress::Running;
            }
            if let Some(done) = self.next_pass() {
                return Progress::Done(done);
            }
            if budget == 0 {
                return Progress::Running;
            }
        }
    }

    /// Ends the pass read through: keeps its point if it is the best so
    /// far, and starts the next pass (`Some`: no next pass, the result).
    fn next_pass(&mut self) -> Option<Option<Smoothed>> {
        self.passes += 1;
        let Some(p) = self.pass.finish(&self.priors, &self.along) else { return Some(self.result(false)) };
        if self.passes == 1 {
            self.filter_cost = p.cost;
        }
        if self.best.as_ref().is_none_or(|(b, _)| p.cost < b.cost) {
            let Some(mut step) = p.step else { return Some(self.result(false)) };
            // One prior σ of drag per step at most: far from the answer
            // the drag's column is a poor guide.
            let d = self.priors.drag_std.max(CONVERGED_DRAG);
            step[DRAG] = step[DRAG].clamp(-d, d);
            let converged = step.fixed_rows::<6>(0).norm() < CONVERGED_STATE
                && step.fixed_rows::<3>(6).norm() < CONVERGED_SPIN
                && step[DRAG].abs() < CONVERGED_DRAG;
            self.best = Some((p, step));
            self.shrink = 1.0;
            if converged {
                return Some(self.result(true));
            }
        } else {
            self.shrink *= 0.5;
        }
        if self.passes >= PASSES {
            return Some(self.result(false));
        }
        let (from, step) = self.best.as_ref().expect("set by the first pass");
        self.pass = Pass::new(&self.prop, from.x + step * self.shrink, self.t0);
        None
    }

    /// The best point (`stepped`: with the short step from it taken, where
    /// the flight is linear enough in the unknowns that the step needs no
    /// pass to check it), where it beats the start.
    fn result(&self, stepped: bool) -> Option<Smoothed> {
        let (best, step) = self.best.as_ref()?;
        if !(stepped || best.cost < self.filter_cost) {
            return None;
        }
        let x = if stepped { best.x + step } else { best.x };
        // Spin and drag are constant in flight; the position and velocity
        // at the last sample move with the step by millimetres at most,
        // and the filter keeps its own.
        let state = BallState { spin: Vec3::new(x[6], x[7], x[8]), ..best.last };
        // The spin's rows of H⁻¹: three solves, not the whole inverse.
        let spin_cov = best.chol.as_ref().map(|c| {
            let unit = SMatrix::<f64, N, 3>::from_fn(|i, j| if i == 6 + j { 1.0 } else { 0.0 });
            c.solve(&unit).fixed_rows::<3>(6).into_owned()
        });
        Some(Smoothed { state, drag: x[DRAG].exp(), spin_cov })
    }
}

/// The whole batch at once ([`Batch`] read to its end).
#[cfg(test)]
pub(crate) fn smooth(prop: &Propagator, window: &[Sample], last: &BallState, priors: &Priors) -> Option<Smoothed> {
    let mut batch = Batch::start(prop, window, last, priors)?;
    loop {
        if let Progress::Done(found) = batch.advance(window, usize::MAX) {
            return found;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;
    use crate::estimator::ekf::{Ekf, EkfNoise};
    use crate::fit::refine::SPIN_PRIOR_STD;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    const PRIORS: Priors = Priors { sigma: 0.002, along_std: 15.0, spin_std: SPIN_PRIOR_STD, drag_std: 0.15 };

    /// A fast topspin flight's samples at 150 Hz with `noise` m per axis.
    fn flight(prop: &Propagator, truth: &BallState, noise: f64, rng: &mut ChaCha8Rng) -> Vec<Sample> {
        (0..50)
            .map(|i| {
                let t = i as f64 / 150.0;
                let n = Vec3::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5);
                Sample { t, pos: prop.fly(truth, t).pos + n * (noise * 12f64.sqrt()) }
            })
            .collect()
    }

    #[test]
    fn noise_free_flight_is_recovered_from_a_wrong_spin() {
        let prop = Calibration::default_cell().propagator();
        let truth =
            BallState::new(Vec3::new(-1.8, 0.05, 0.35), Vec3::new(5.5, -0.1, 0.9), Vec3::new(10.0, 600.0, -15.0));
        let window: Vec<Sample> =
            (0..50).map(|i| Sample { t: i as f64 / 150.0, pos: prop.fly(&truth, i as f64 / 150.0).pos }).collect();
        let end = prop.fly(&truth, window.last().unwrap().t);
        let mut wrong = end;
        wrong.spin *= 0.8;
        let s = smooth(&prop, &window, &wrong, &PRIORS).expect("beats the wrong spin").state;
        assert!((s.spin - end.spin).norm() < 0.01 * end.spin.norm(), "{:?} vs {:?}", s.spin, end.spin);
        assert!((s.pos - end.pos).norm() < 1e-4);
    }

    #[test]
    fn the_right_state_is_kept() {
        let prop = Calibration::default_cell().propagator();
        let truth = BallState::new(Vec3::new(-1.8, 0.0, 0.35), Vec3::new(6.0, 0.0, 0.8), Vec3::new(0.0, -300.0, 0.0));
        let window: Vec<Sample> =
            (0..40).map(|i| Sample { t: i as f64 / 150.0, pos: prop.fly(&truth, i as f64 / 150.0).pos }).collect();
        let end = prop.fly(&truth, window.last().unwrap().t);
        // On noise-free samples the truth stays (or moves by the
        // integration's rounding) where no prior pulls it (the spin's size
        // prior moves it by 10⁻⁶ of the drag).
        let unpulled = Priors { spin_std: 1e9, ..PRIORS };
        if let Some(Smoothed { state: s, drag, .. }) = smooth(&prop, &window, &end, &unpulled) {
            assert!((drag - 1.0).abs() < 1e-6, "{drag}");
            assert!((s.spin - end.spin).norm() < 1e-3 && (s.pos - end.pos).norm() < 1e-7, "{s:?} vs {end:?}");
        }
        assert_eq!(smooth(&prop, &window[..5], &end, &PRIORS), None, "too short to say");
    }

    /// A heavier ball than the physics given: its drag is read with its spin.
    #[test]
    fn the_flights_own_drag_is_read() {
        let prop = Calibration::default_cell().propagator();
        let heavy = Propagator { flight: prop.flight.scaled(FlightScales { drag: 1.3, lift: 1.0 }), ..prop };
        // Spin across the flight (along it the prior has a say).
        let vel = Vec3::new(6.0, 0.2, 0.8);
        let spin = Vec3::new(0.0, 300.0, 40.0);
        let spin = spin - vel * (vel.dot(&spin) / vel.norm_squared());
        let truth = BallState::new(Vec3::new(-1.8, 0.0, 0.35), vel, spin);
        let window: Vec<Sample> =
            (0..70).map(|i| Sample { t: i as f64 / 150.0, pos: heavy.fly(&truth, i as f64 / 150.0).pos }).collect();
        let end = heavy.fly(&truth, window.last().unwrap().t);
        let found = smooth(&prop, &window, &BallState { spin: end.spin * 0.9, ..end }, &PRIORS).expect("improves");
        assert!((found.drag - 1.3).abs() < 0.01, "drag ×{:.3}", found.drag);
        assert!(
            (found.state.spin - end.spin).norm() < 0.01 * end.spin.norm(),
            "{:?} vs {:?}",
            found.state.spin,
            end.spin
        );
        // Held where the prior says so: the spin takes what it can.
        let held = Priors { drag_std: 0.0, ..PRIORS };
        let found = smooth(&prop, &window, &end, &held).expect("improves on the truth in the wrong air");
        assert!((found.drag - 1.0).abs() < 1e-6);
    }

    /// Read in shares of [`SAMPLES_PER_STEP`], the batch finds exactly what
    /// it finds read at once, and a window that grew meanwhile changes
    /// nothing.
    #[test]
    fn reading_in_shares_finds_what_reading_at_once_does() {
        let prop = Calibration::default_cell().propagator();
        let truth =
            BallState::new(Vec3::new(-1.8, 0.05, 0.35), Vec3::new(5.5, -0.1, 0.9), Vec3::new(10.0, 500.0, -15.0));
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut window = flight(&prop, &truth, 0.002, &mut rng);
        let end = prop.fly(&truth, window[39].t);
        let wrong = BallState { spin: end.spin * 0.85, ..end };
        let at_once = smooth(&prop, &window[..40], &wrong, &PRIORS).expect("improves");
        let mut batch = Batch::start(&prop, &window[..40], &wrong, &PRIORS).expect("starts");
        window.truncate(40);
        let mut steps = 0;
        let found = loop {
            steps += 1;
            window.push(Sample { t: 10.0 + steps as f64, pos: Vec3::zeros() }); // later samples: not read
            if let Progress::Done(found) = batch.advance(&window, SAMPLES_PER_STEP) {
                break found;
            }
        };
        assert_eq!(found, Some(at_once));
        // 40 samples a pass, 32 a step: read in shares.
        assert!(steps >= 2, "{steps} steps");
    }

    /// The search stops with a step short enough to take unchecked: started
    /// again from its answer (its drag read anew), the batch is done within
    /// two passes and moves the spin by less than [`CONVERGED_SPIN`].
    #[test]
    fn the_answer_is_where_the_next_step_is_short() {
        let prop = Calibration::default_cell().propagator();
        let truth = BallState::new(Vec3::new(-1.8, 0.05, 0.35), Vec3::new(5.5, -0.1, 0.9), Vec3::new(0.0, 450.0, 60.0));
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let window = flight(&prop, &truth, 0.002, &mut rng);
        let end = prop.fly(&truth, window.last().unwrap().t);
        let run = |from: &BallState| {
            let mut batch = Batch::start(&prop, &window, from, &PRIORS).expect("starts");
            loop {
                if let Progress::Done(found) = batch.advance(&window, usize::MAX) {
                    break (found.expect("an answer"), batch.passes);
                }
            }
        };
        let (found, passes) = run(&BallState { spin: end.spin * 0.8, ..end });
        assert!(passes < PASSES, "{passes} passes: the search ran out");
        let (again, passes) = run(&found.state);
        assert!(passes <= 2, "{passes} passes from the answer");
        assert!((again.state.spin - found.state.spin).norm() < CONVERGED_SPIN, "{again:?} vs {found:?}");
        assert!((again.state.spin - truth.spin).norm() < 0.05 * truth.spin.norm(), "{again:?}");
    }

    /// The spin's covariance is the scatter of what the batch reads: over
    /// flights that differ only in their noise, the squared errors across
    /// the flight weighed by it average two (χ² with two degrees of
    /// freedom; along the flight the prior, right here, has the say).
    #[test]
    fn the_spin_covariance_matches_the_scatter() {
        let prop = Calibration::default_cell().propagator();
        let vel = Vec3::new(5.5, -0.1, 0.9);
        let spin = Vec3::new(20.0, 350.0, -40.0);
        let truth =
            BallState::new(Vec3::new(-1.8, 0.05, 0.35), vel, spin - vel * (vel.dot(&spin) / vel.norm_squared()));
        // A basis across the flight.
        let along = vel.normalize();
        let b1 = along.cross(&Vec3::z()).normalize();
        let across = nalgebra::Matrix3x2::from_columns(&[b1, along.cross(&b1)]);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut nees = Vec::new();
        for _ in 0..40 {
            let window = flight(&prop, &truth, 0.002, &mut rng);
            let end = prop.fly(&truth, window.last().unwrap().t);
            let found = smooth(&prop, &window, &BallState { spin: end.spin * 0.9, ..end }, &PRIORS).expect("improves");
            let e = across.transpose() * (found.state.spin - truth.spin);
            let cov = across.transpose() * found.spin_cov.expect("a covariance") * across;
            nees.push((e.transpose() * cov.try_inverse().expect("invertible") * e)[0]);
        }
        let mean = nees.iter().sum::<f64>() / nees.len() as f64;
        // 40 draws of χ²₂: the mean's σ is 0.32.
        assert!((1.2..2.9).contains(&mean), "mean {mean:.2}");
    }

    /// The filter settles low on fast topspin; the batch does not.
    #[test]
    fn fast_topspin_is_read_without_the_filters_bias() {
        let prop = Calibration::default_cell().propagator();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (mut ekf_ratio, mut batch_ratio) = (Vec::new(), Vec::new());
        for _ in 0..12 {
            let spin = Vec3::new(0.0, 560.0 + 80.0 * rng.random::<f64>(), 0.0);
            let truth = BallState::new(Vec3::new(-1.8, 0.0, 0.35), Vec3::new(5.5, 0.0, 0.9), spin);
            let window = flight(&prop, &truth, 0.002, &mut rng);
            // A window of free flight: the filter would bounce where the
            // samples (flown without events) passed through the table.
            let window: Vec<Sample> = window.into_iter().take_while(|s| s.pos.z > 0.05).collect();
            let mut ekf =
                Ekf::new(0.0, &BallState { spin: Vec3::zeros(), ..truth }, 0.004, 0.6, 600.0, EkfNoise::default());
            for s in &window {
                ekf.predict(&prop, s.t);
                ekf.update(&s.pos);
            }
            let filtered = ekf.state();
            let batch = smooth(&prop, &window, &filtered, &PRIORS).map_or(filtered, |s| s.state);
            ekf_ratio.push(filtered.spin.y / spin.y);
            batch_ratio.push(batch.spin.y / spin.y);
        }
        let median = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (e, b) = (median(&mut ekf_ratio), median(&mut batch_ratio));
        assert!(e < 0.95, "the filter alone reads {e:.3} of the spin: is its bias gone? Then this module may be too");
        assert!((b - 1.0).abs() < 0.04, "the batch reads {b:.3} of the spin");
    }

    /// A short window from a fast tracker (24 samples at 380 Hz, 63 ms):
    /// the flight's bend says little about the spin's size, and under a
    /// saturating lift a larger spin costs the residuals next to nothing.
    /// The size prior keeps what the batch hands the filter a ball's spin.
    #[test]
    fn a_short_window_reads_a_spin_a_ball_can_have() {
        let prop = Calibration::default_cell().propagator();
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let mut largest = |priors: &Priors| -> f64 {
            let mut most: f64 = 0.0;
            for _ in 0..20 {
                let spin = Vec3::new(30.0 * (rng.random::<f64>() - 0.5), 150.0 + 450.0 * rng.random::<f64>(), -20.0);
                let truth = BallState::new(Vec3::new(-1.8, 0.0, 0.35), Vec3::new(5.5, 0.1, 0.9), spin);
                let window: Vec<Sample> = (0..24)
                    .map(|i| {
                        let t = i as f64 / 380.0;
                        let n =
                            Vec3::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5);
                        Sample { t, pos: prop.fly(&truth, t).pos + n * (0.002 * 12f64.sqrt()) }
                    })
                    .collect();
                let mut ekf =
                    Ekf::new(0.0, &BallState { spin: Vec3::zeros(), ..truth }, 0.004, 0.6, 600.0, EkfNoise::default());
                for s in &window {
                    ekf.predict(&prop, s.t);
                    ekf.update(&s.pos);
                }
                if let Some(found) = smooth(&prop, &window, &ekf.state(), priors) {
                    most = most.max(found.state.spin.norm());
                }
            }
            most
        };
        let with = largest(&PRIORS);
        let without = largest(&Priors { spin_std: 1e9, ..PRIORS });
        assert!(with < 1500.0, "the batch read {with:.0} rad/s");
        // Without it the same windows run off (1.5·10⁷ rad/s when written).
        assert!(without > 1e4, "{without:.0} rad/s without the prior: is this test still needed?");
    }

    /// When batches are due, on a virtual clock: at 150 Hz and faster by
    /// count (24 samples, then every 8); a slower tracker after as much
    /// flight (150 ms, then 50 ms), never under 16 and 4 samples.
    #[test]
    fn batches_come_after_as_much_flight_at_a_slower_tracker() {
        let window = |rate: f64, n: usize| -> Vec<Sample> {
            (0..n).map(|i| Sample { t: 2.0 + i as f64 / rate, pos: Vec3::zeros() }).collect()
        };
        let first = |rate: f64| (1..200).find(|&n| due(&window(rate, n), 0)).unwrap();
        let next = |rate: f64, from: usize| (from + 1..200).find(|&n| due(&window(rate, n), from)).unwrap();
        assert_eq!((first(150.0), next(150.0, 24)), (24, 32));
        assert_eq!((first(380.0), next(380.0, 24)), (24, 32));
        // 90 Hz: 16 samples span 167 ms, then 5 more 56 ms.
        assert_eq!((first(90.0), next(90.0, 16)), (16, 21));
        // 30 Hz: the floors hold.
        assert_eq!((first(30.0), next(30.0, 16)), (16, 20));
    }
}
