//! What the estimator learns across a session: the things that
//! do not change from one ball to the next — the table's restitution e and
//! friction μ, read from the bounces it sees, the air's drag, read from
//! each flight's deceleration, and how much of the velocity after a bounce
//! the table model leaves unexplained (the filter's bounce noise, per axis:
//! the mean square of each bounce's residual less what the state's
//! uncertainty before it and the measurement after it explain). Bounded
//! (each value stays inside a plausible range), robust to a bad ball (one
//! ball moves a value by at most a fixed step), with a fixed memory, and
//! reset with the estimator (a restart or a new configuration).
//!
//! It also learns the spin the table meets per unit of the spin a flight
//! shows ([`LearnedSession::spin`], [`super::spin_prior`]), the next balls' spin
//! prior. A bounce no table explains (a net-cord ball, the table's edge, a
//! tracker jump) teaches nothing ([`LearnedSession::unexplained`],
//! [`bounce_explained`]); one explained only by a spin off the prior's
//! scale teaches the spin prior alone. [`LearnedSession::surprised`]
//! counts the bounces flown again with the spin's size free.
//!
//! The measurements are bounded in work: the session's drag once per ball
//! when it bounces (what the ball's batches read, `super::smooth`; where
//! none has, one cubic over the window, [`drag_from_flight`], which reads
//! 2–5 % low), the table and the bounce noise when its track ends; a
//! ball's own drag (weighed against the session's for the rest of its
//! flight, [`LearnConfig::ball_drag_weight`]) every
//! [`LearnConfig::ball_drag_every`] samples before its bounce, until a
//! batch has read it.

use super::spin_prior::SpinPrior;
use crate::fit::Sample;
use crate::fit::poly::Cubic;
use crate::physics::{BallState, BounceModel, FlightModel, Vec3};

/// Settings of the session learning.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LearnConfig {
    /// Learn at all (off: every ball flies with the calibration).
    pub enabled: bool,
    /// Balls after which a new one counts with weight 1/`memory`.
    pub memory: u32,
    /// Fewest samples a measurement is made from.
    pub min_samples: usize,
    /// Weight of a ball's own drag, read from its flight so far, against
    /// the session's for the rest of that ball's flight (0: the session's
    /// alone; balls differ by their surface and seam).
    pub ball_drag_weight: f64,
    /// The ball's own drag is reread every this many accepted samples
    /// before its bounce (and at the bounce).
    pub ball_drag_every: usize,
    /// Learn the spin the table meets per unit of the spin a flight shows
    /// ([`LearnedSession::spin`]), and bounce the next balls with it.
    pub spin: bool,
    /// With `spin`: read each ball's spin from its return, against the
    /// planned stroke (`estimator::returns`). Only where a robot plays the
    /// plans (the daemon, the virtual cell): off for offline streams, whose
    /// returns another racket made.
    pub returns: bool,
}

impl Default for LearnConfig {
    fn default() -> Self {
        LearnConfig {
            enabled: true,
            memory: 24,
            min_samples: 12,
            ball_drag_weight: 0.5,
            ball_drag_every: 8,
            spin: true,
            returns: false,
        }
    }
}

impl LearnConfig {
    /// Nothing learned: every ball flies with the calibration.
    pub const OFF: LearnConfig = LearnConfig {
        enabled: false,
        memory: 8,
        min_samples: 12,
        ball_drag_weight: 0.0,
        ball_drag_every: 8,
        spin: false,
        returns: false,
    };

    /// The drag multiplier one ball flies with: the session's, moved
    /// towards the ball's own measurement by [`Self::ball_drag_weight`],
    /// within the session's bounds.
    pub fn ball_drag(&self, session: &Learned, measured: Option<f64>) -> f64 {
        match measured {
            Some(m) if m.is_finite() && self.ball_drag_weight > 0.0 => {
                let own = m.clamp(session.bounds.0, session.bounds.1);
                session.value + self.ball_drag_weight.min(1.0) * (own - session.value)
            }
            _ => session.value,
        }
    }
}

/// One learned value: a running mean whose steps are clipped (a bad ball
/// moves it at most `max_step / n`) and whose result stays within bounds.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Learned {
    /// The current value.
    pub value: f64,
    /// Measurements taken in.
    pub count: u32,
    bounds: (f64, f64),
    max_step: f64,
}

impl Learned {
    fn new(value: f64, bounds: (f64, f64), max_step: f64) -> Self {
        Learned { value, count: 0, bounds, max_step }
    }

    fn take(&mut self, measured: f64, memory: u32) {
        if !measured.is_finite() {
            return;
        }
        self.count = self.count.saturating_add(1);
        let weight = 1.0 / f64::from(self.count.min(memory) + 1);
        let step = (measured - self.value).clamp(-self.max_step, self.max_step);
        self.value = (self.value + weight * step).clamp(self.bounds.0, self.bounds.1);
    }
}

/// The session's learned drag multiplier and table.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LearnedSession {
    /// Multiplier of the calibrated drag (C_D 0.40–0.55 spans ×0.85–1.25
    /// about 0.447; bounded ×0.6–1.8).
    pub drag: Learned,
    /// Table restitution e (bounded 0.7–0.99).
    pub restitution: Learned,
    /// Ball–table friction μ (bounded 0.05–0.6).
    pub friction: Learned,
    /// What the table model leaves unexplained of the velocity just after
    /// a bounce, per axis, (m/s)² (the filter's
    /// [`super::ekf::EkfNoise::bounce_vel`]; bounded 0.002–0.5).
    pub bounce_vel: [Learned; 3],
    /// The spin the table meets per unit of the spin a flight shows.
    pub spin: SpinPrior,
    /// Bounces no table explained (learned nothing from).
    pub unexplained: u32,
    /// Bounces whose first samples surprised the filter, flown again with
    /// the spin's size free (`estimator::SURPRISE_SHARE`).
    pub surprised: u32,
    /// Balls whose spin their return read (`estimator::returns`).
    pub returns_read: u32,
}

/// χ² (3 dof) at 99.9 %: a bounce whose velocity after it lies farther
/// from every table tried is not explained.
pub(crate) const BOUNCE_GATE_CHI2: f64 = 16.27;

impl LearnedSession {
    /// A session that starts from the calibration's table and the
    /// filter's bounce noise (per axis, (m/s)²).
    pub fn new(bounce: &BounceModel, bounce_vel_start: &Vec3) -> Self {
        LearnedSession {
            drag: Learned::new(1.0, (0.6, 1.8), 0.3),
            restitution: Learned::new(bounce.restitution, (0.7, 0.99), 0.08),
            friction: Learned::new(bounce.friction, (0.05, 0.6), 0.1),
            bounce_vel: [0, 1, 2].map(|k| Learned::new(bounce_vel_start[k], (0.002, 0.5), 0.1)),
            spin: SpinPrior::default(),
            unexplained: 0,
            surprised: 0,
            returns_read: 0,
        }
    }

    /// The extra velocity variance at a bounce learned so far, per axis.
    pub fn bounce_noise(&self) -> Vec3 {
        Vec3::new(self.bounce_vel[0].value, self.bounce_vel[1].value, self.bounce_vel[2].value)
    }

    /// Takes one ball's bounce residual: `residual` the velocity seen just
    /// after it less the one its table predicted, `explained` the variance
    /// per axis that the state's uncertainty before it and the measurement
    /// of the velocity after it account for. What is left is the table
    /// model's own (innovation-based noise estimation: the mean of r² less
    /// its explained part).
    pub(crate) fn take_bounce_residual(&mut self, residual: &Vec3, explained: &Vec3, cfg: &LearnConfig) {
        for k in 0..3 {
            self.bounce_vel[k].take(residual[k] * residual[k] - explained[k], cfg.memory);
        }
    }

    /// The table as learned so far (spin scale 1: a ball's own comes
    /// with its flight, [`SpinPrior::scale_at`]).
    pub fn bounce_model(&self, calibrated: &BounceModel) -> BounceModel {
        BounceModel::new(self.restitution.value, self.friction.value, calibrated.radius)
    }

    /// Takes one ball's drag multiplier.
    pub(crate) fn take_drag(&mut self, measured: f64, cfg: &LearnConfig) {
        self.drag.take(measured, cfg.memory);
    }

    /// Takes one ball's bounce: `before` at contact (from the filter), the
    /// velocity just after it (from the samples after the bounce).
    pub(crate) fn take_bounce(&mut self, before: &BallState, after_vel: &Vec3, radius: f64, cfg: &LearnConfig) {
        let Some((e, mu)) = table_from_bounce(before, after_vel, radius) else { return };
        self.restitution.take(e, cfg.memory);
        if let Some(mu) = mu {
            self.friction.take(mu, cfg.memory);
        }
    }
}

/// The drag multiplier that explains the deceleration along the flight of
/// `samples` (pure flight, time-ordered): along the velocity the Magnus
/// force vanishes, so P″·v̂ = −k_D·s·‖P′‖² − g·v̂_z, solved for s by least
/// squares over the samples with the cubic's P′ and P″ (the paper's
/// construction, for the drag).
pub(crate) fn drag_from_flight(samples: &[Sample], flight: &FlightModel, min_samples: usize) -> Option<f64> {
    if samples.len() < min_samples {
        return None;
    }
    let cubic = Cubic::fit(samples.iter())?;
    let (mut xy, mut xx) = (0.0, 0.0);
    for s in samples {
        let v = cubic.vel(s.t);
        let speed = v.norm();
        if speed < 1.0 {
            continue;
        }
        let along = v / speed;
        let x = flight.k_d() * speed * speed;
        let y = -(cubic.acc(s.t).dot(&along) + flight.gravity() * along.z);
        xy += x * y;
        xx += x * x;
    }
    (xx > 0.0).then(|| xy / xx).filter(|s| s.is_finite() && *s > 0.0)
}

/// Whether `table` explains a bounce: the squared Mahalanobis distance
/// of the velocity after it from the table's prediction, `var` per axis,
/// within [`BOUNCE_GATE_CHI2`].
pub(crate) fn bounce_explained(before: &BallState, after: &Vec3, var: &Vec3, table: &BounceModel) -> bool {
    let v = table.apply(before).vel;
    let d2: f64 = (0..3).map(|k| (v[k] - after[k]).powi(2) / var[k].max(1e-6)).sum();
    d2.is_finite() && d2 <= BOUNCE_GATE_CHI2
}

/// The velocity at `t` of a cubic through `samples` (after a bounce), and
/// its variance per axis for samples with per-axis noise `sigma`.
pub(crate) fn velocity_at(samples: &[Sample], t: f64, min_samples: usize, sigma: f64) -> Option<(Vec3, f64)> {
    if samples.len() < min_samples {
        return None;
    }
    let cubic = Cubic::fit(samples.iter())?;
    let spread = cubic.vel_spread(samples.iter(), t)?;
    Some((cubic.vel(t), sigma * sigma * spread))
}

/// e and (where the contact slid) μ of one bounce, inverting the bounce
/// model (DESIGN §3): v_z⁺ = −e v_z⁻; the tangential velocity changes by
/// −α·v_T with v_T the slip at the contact and α = μ(1+e)|v_z⁻|/‖v_T‖ while
/// sliding (α < 2/5). μ is `None` where the ball rolled off or barely slid.
pub(crate) fn table_from_bounce(before: &BallState, after_vel: &Vec3, radius: f64) -> Option<(f64, Option<f64>)> {
    let (v, w) = (before.vel, before.spin);
    if v.z > -0.5 {
        return None;
    }
    let e = -after_vel.z / v.z;
    let slip = nalgebra::Vector2::new(v.x - radius * w.y, v.y + radius * w.x);
    let change = nalgebra::Vector2::new(after_vel.x - v.x, after_vel.y - v.y);
    let slip_speed = slip.norm();
    let mu = (slip_speed > 0.5)
        .then(|| -change.dot(&slip) / (slip_speed * slip_speed))
        .filter(|alpha| *alpha > 0.02 && *alpha < 0.3)
        .map(|alpha| alpha * slip_speed / ((1.0 + e) * v.z.abs()));
    Some((e, mu))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;
    use crate::physics::{Event, FlightScales, StopAt};

    #[test]
    fn one_bounce_gives_back_e_and_mu() {
        let b = BounceModel::new(0.9, 0.2, 0.02);
        // Sliding: backspin.
        let before = BallState::new(Vec3::zeros(), Vec3::new(5.0, 0.3, -3.0), Vec3::new(0.0, -200.0, 0.0));
        let (e, mu) = table_from_bounce(&before, &b.apply(&before).vel, 0.02).unwrap();
        assert!((e - 0.9).abs() < 1e-12 && (mu.unwrap() - 0.2).abs() < 1e-12, "{e} {mu:?}");
        // Rolling (topspin matching the speed): μ not measurable.
        let rolling = BallState::new(Vec3::zeros(), Vec3::new(5.0, 0.0, -3.0), Vec3::new(0.0, 250.0, 0.0));
        let after = b.apply(&rolling).vel;
        assert_eq!(table_from_bounce(&rolling, &after, 0.02).unwrap().1, None);
        // Not falling into the table: nothing.
        assert_eq!(table_from_bounce(&BallState { vel: Vec3::new(5.0, 0.0, 0.1), ..rolling }, &after, 0.02), None);
    }

    #[test]
    fn a_bounce_no_table_explains_is_told_apart() {
        let table = BounceModel::new(0.92, 0.2, 0.02);
        let var = Vec3::repeat(0.03f64.powi(2));
        let before = BallState::new(Vec3::zeros(), Vec3::new(5.0, 0.0, -3.0), Vec3::new(0.0, -300.0, 0.0));
        let after = table.apply(&before).vel;
        assert!(bounce_explained(&before, &after, &var, &table));
        // A net-cord ball, or a tracker jump at the bounce.
        assert!(!bounce_explained(&before, &(after + Vec3::new(-2.0, 1.0, 0.0)), &var, &table));
    }

    #[test]
    fn drag_is_read_from_the_deceleration() {
        let cal = Calibration::default_cell();
        let prop = cal.propagator().with_scales(FlightScales { drag: 1.3, lift: 1.0 });
        let mut s = BallState::new(Vec3::new(-1.5, 0.0, 0.3), Vec3::new(7.0, 0.0, 1.5), Vec3::new(0.0, 300.0, 20.0));
        let mut t = 0.0;
        let mut samples = Vec::new();
        while t < 0.25 {
            samples.push(Sample::new(t, s.pos));
            let next = StopAt::time(t + 1.0 / 150.0);
            assert!(matches!(prop.advance(&mut s, &mut t, &next), Event::TimeLimit { .. }));
        }
        let d = drag_from_flight(&samples, &cal.propagator().flight, 12).unwrap();
        assert!((d - 1.3).abs() < 0.03, "{d}");
        assert_eq!(drag_from_flight(&samples[..5], &cal.propagator().flight, 12), None);
    }

    #[test]
    fn a_ball_flies_with_its_own_drag_weighed_against_the_sessions() {
        let mut s = LearnedSession::new(&BounceModel::new(0.95, 0.14, 0.02), &Vec3::repeat(0.05));
        s.drag.value = 1.1;
        let cfg = LearnConfig { ball_drag_weight: 0.5, ..LearnConfig::default() };
        assert!((cfg.ball_drag(&s.drag, Some(1.3)) - 1.2).abs() < 1e-12);
        // A wild measurement counts only up to the session's bound (1.8).
        assert!((cfg.ball_drag(&s.drag, Some(5.0)) - 1.45).abs() < 1e-12);
        assert_eq!(cfg.ball_drag(&s.drag, None), 1.1);
        assert_eq!(cfg.ball_drag(&s.drag, Some(f64::NAN)), 1.1);
        assert_eq!(LearnConfig { ball_drag_weight: 0.0, ..cfg }.ball_drag(&s.drag, Some(1.3)), 1.1);
    }

    #[test]
    fn learning_is_bounded_and_a_bad_ball_moves_it_little() {
        let cfg = LearnConfig::default();
        let mut s = LearnedSession::new(&BounceModel::new(0.95, 0.14, 0.02), &Vec3::repeat(0.05));
        let before = BallState::new(Vec3::zeros(), Vec3::new(5.0, 0.0, -3.0), Vec3::new(0.0, -150.0, 0.0));
        let after = BounceModel::new(0.88, 0.3, 0.02).apply(&before).vel;
        for _ in 0..40 {
            s.take_bounce(&before, &after, 0.02, &cfg);
        }
        assert!((s.restitution.value - 0.88).abs() < 0.005 && (s.friction.value - 0.3).abs() < 0.01, "{s:?}");
        // Past the memory: a new ball weighs 1/(memory + 1).
        for _ in 0..cfg.memory + 4 {
            s.take_drag(1.1, &cfg);
        }
        let before = s;
        s.take_drag(50.0, &cfg);
        s.restitution.take(f64::NAN, cfg.memory);
        assert!(s.drag.value - before.drag.value <= 0.3 / f64::from(cfg.memory + 1) + 1e-12);
        assert_eq!(s.restitution, before.restitution);
        for _ in 0..100 {
            s.take_drag(50.0, &cfg);
        }
        assert_eq!(s.drag.value, 1.8);
    }

    /// The bounce noise is the mean of the residual's square less what
    /// the state and the measurement explain, per axis, within its bounds.
    #[test]
    fn the_bounce_noise_is_what_the_residuals_leave_unexplained() {
        let cfg = LearnConfig::default();
        let mut s = LearnedSession::new(&BounceModel::new(0.95, 0.14, 0.02), &Vec3::repeat(0.05));
        let explained = Vec3::new(0.01, 0.01, 0.01);
        // Residuals of ±0.3 m/s sideways, 0.1 along the flight, none up.
        for k in 0..200 {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            s.take_bounce_residual(&Vec3::new(0.1 * sign, 0.3 * sign, 0.0), &explained, &cfg);
        }
        let n = s.bounce_noise();
        // 0.01 − 0.01: nothing left, at the bound.
        assert_eq!(n.x, 0.002, "{n:?}");
        assert!((n.y - (0.09 - 0.01)).abs() < 1e-3, "{n:?}");
        assert_eq!(n.z, 0.002, "bounded below");
        assert_eq!(s.bounce_vel[1].count, 200);
    }
}
