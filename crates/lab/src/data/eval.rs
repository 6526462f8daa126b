//! The real-data evaluation: predict from the samples before the
//! net only, then compare with what the real ball did.
//!
//! For each trajectory (in the table frame): the leading samples with x < 0
//! go to a [`Predictor`], which returns the ball's state at its last sample
//! (spin included). The harness propagates that state with the configured
//! [`Propagator`] and measures
//!
//! - (a) the bounce error: predicted first table contact vs the contact
//!   detected in the recording ([`detect_bounces`]), in the xy plane, mm;
//! - (b) the error 0.3 s ahead: predicted position at t_last + 0.3 s vs the
//!   recorded position linearly interpolated at that time, 3D, mm. Skipped
//!   where the recording ends earlier or has a gap there.
//!
//! Results are reported per set (mean, median, std, count) with the reasons
//! for every skipped trajectory counted.

use topspin_core::physics::{BallState, Event, FlightScales, Propagator, StopAt, Vec3};

use super::frame::{BounceSearch, DetectedBounce, LabToTable, detect_bounces};
use super::mpi::{RealTrajectory, SETS, median};
use super::polyfit::{eval, eval_deriv, polyfit};

/// What a predictor says about a ball from its observations.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Prediction {
    /// Time of the state, s (the last sample's time).
    pub t: f64,
    /// Position, velocity and spin at `t`, table frame.
    pub state: BallState,
    /// The drag and lift the state flies with, as multipliers of the
    /// calibration (a refined fit reads them per flight).
    pub scales: FlightScales,
}

impl Prediction {
    /// A state that flies with the calibration itself.
    pub fn calibrated(t: f64, state: BallState) -> Self {
        Prediction { t, state, scales: FlightScales::ONE }
    }
}

/// Anything that turns observations (table frame, increasing t) into a
/// state to propagate. `None`: no prediction from these samples.
pub trait Predictor {
    /// The ball's state at the last of `samples` (time in s, position in m,
    /// table frame), or `None` for no prediction.
    fn predict(&self, samples: &[(f64, Vec3)]) -> Option<Prediction>;
}

impl<P: Predictor + ?Sized> Predictor for &P {
    fn predict(&self, samples: &[(f64, Vec3)]) -> Option<Prediction> {
        (**self).predict(samples)
    }
}

/// The spin-free baseline: a least-squares cubic per axis through the
/// samples (time centred), position and velocity taken at the last sample,
/// spin zero.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct CubicBaseline;

impl Predictor for CubicBaseline {
    fn predict(&self, samples: &[(f64, Vec3)]) -> Option<Prediction> {
        let (pos, vel, t) = cubic_state(samples)?;
        Some(Prediction::calibrated(t, BallState::new(pos, vel, Vec3::zeros())))
    }
}

/// Position and velocity at the last sample from a cubic per axis.
pub(crate) fn cubic_state(samples: &[(f64, Vec3)]) -> Option<(Vec3, Vec3, f64)> {
    let &(t_last, _) = samples.last()?;
    if samples.len() < 4 {
        return None;
    }
    let t_mean = samples.iter().map(|s| s.0).sum::<f64>() / samples.len() as f64;
    let tau = t_last - t_mean;
    let mut pos = Vec3::zeros();
    let mut vel = Vec3::zeros();
    let mut pts = Vec::with_capacity(samples.len());
    for axis in 0..3 {
        pts.clear();
        pts.extend(samples.iter().map(|(t, p)| (t - t_mean, p[axis])));
        let c = polyfit::<4>(&pts)?;
        pos[axis] = eval(&c, tau);
        vel[axis] = eval_deriv(&c, tau);
    }
    Some((pos, vel, t_last))
}

/// A trajectory in the table frame with what the evaluation needs from it,
/// computed once.
#[derive(Clone, Debug, PartialEq)]
pub struct PreparedTrajectory {
    /// The subset (`backspin`, `topspin`, `no_spin`, `robot_no_spin`).
    pub set: String,
    /// The file number within the subset.
    pub index: usize,
    /// All samples, table frame.
    pub samples: Vec<(f64, Vec3)>,
    /// How many leading samples lie before the net (x < 0).
    pub pre_net: usize,
    /// The first table contact in the recording after the pre-net samples.
    pub bounce: Option<DetectedBounce>,
}

/// Moves `trajs` into the table frame and finds their first bounces.
pub fn prepare<'a>(trajs: impl IntoIterator<Item = &'a RealTrajectory>, frame: &LabToTable) -> Vec<PreparedTrajectory> {
    trajs
        .into_iter()
        .map(|tr| {
            let samples = frame.samples(&tr.samples);
            let pre_net = samples.iter().take_while(|(_, p)| p.x < 0.0).count();
            let t_cut = samples.get(pre_net.max(1) - 1).map_or(f64::NEG_INFINITY, |s| s.0);
            let bounce = detect_bounces(&samples, &BounceSearch::table()).into_iter().find(|b| b.t > t_cut);
            PreparedTrajectory { set: tr.set.clone(), index: tr.index, samples, pre_net, bounce }
        })
        .collect()
}

/// Settings of the evaluation.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct EvalConfig {
    /// Propagates the predicted state (its physics is what calibration
    /// tunes).
    pub propagator: Propagator,
    /// How far ahead of the last used sample the position is compared, s.
    pub horizon: f64,
    /// Fewest pre-net samples for a trajectory to be used.
    pub min_samples: usize,
    /// The real position at the horizon is interpolated only between
    /// samples at most this far apart, s.
    pub max_interp_gap: f64,
    /// Give up looking for the predicted bounce after this long, s.
    pub max_flight: f64,
}

/// The default horizon for (b), s.
pub(crate) const HORIZON: f64 = 0.3;
/// The default fewest pre-net samples.
pub(crate) const MIN_PRE_NET_SAMPLES: usize = 10;

impl EvalConfig {
    /// The default settings around `propagator`: horizon 0.3 s, at least 10
    /// pre-net samples, interpolation across gaps of up to 0.03 s, the
    /// predicted bounce searched for 2 s.
    pub fn new(propagator: Propagator) -> Self {
        EvalConfig {
            propagator,
            horizon: HORIZON,
            min_samples: MIN_PRE_NET_SAMPLES,
            max_interp_gap: 0.03,
            max_flight: 2.0,
        }
    }
}

/// What happened to one trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct TrajectoryResult {
    /// The subset the trajectory comes from.
    pub set: String,
    /// The file number within the subset.
    pub index: usize,
    /// Pre-net samples handed to the predictor.
    pub samples_used: usize,
    /// The predictor's output (`None`: too few samples or it declined).
    pub prediction: Option<Prediction>,
    /// Predicted first contact (t, point), table frame.
    pub predicted_bounce: Option<(f64, Vec3)>,
    /// Detected real contact.
    pub real_bounce: Option<(f64, Vec3)>,
    /// (a) xy distance between the two contacts, mm.
    pub bounce_error_mm: Option<f64>,
    /// Predicted position at t_last + horizon, table frame, m.
    pub predicted_ahead: Option<Vec3>,
    /// Recorded position at t_last + horizon (interpolated), table frame, m.
    pub real_ahead: Option<Vec3>,
    /// (b) 3D distance at t_last + horizon, mm.
    pub ahead_error_mm: Option<f64>,
}

/// Mean, median, sample standard deviation and count of errors, mm.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Stats {
    /// Number of values.
    pub count: usize,
    /// Arithmetic mean (NaN when empty).
    pub mean: f64,
    /// Median (NaN when empty).
    pub median: f64,
    /// Sample standard deviation, divisor n − 1 (NaN with fewer than two
    /// values).
    pub std: f64,
}

impl Stats {
    /// The statistics of `v`.
    pub fn of(v: &[f64]) -> Self {
        let n = v.len();
        let mean = v.iter().sum::<f64>() / n as f64;
        let var = if n > 1 { v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64 } else { f64::NAN };
        Stats { count: n, mean, median: median(&mut v.to_vec()), std: var.sqrt() }
    }
}

impl std::fmt::Display for Stats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "n={:>2} mean {:>6.1} median {:>6.1} std {:>6.1}", self.count, self.mean, self.median, self.std)
    }
}

/// The results of one group (a set, or all).
#[derive(Clone, Debug, PartialEq)]
pub struct GroupReport {
    /// The set's name, or `all`.
    pub name: String,
    /// Trajectories in the group.
    pub trajectories: usize,
    /// With enough pre-net samples.
    pub used: usize,
    /// The predictor declined.
    pub no_prediction: usize,
    /// No real contact in the recording (it ends first).
    pub no_real_bounce: usize,
    /// A real contact exists but the prediction has none (flies off the
    /// table or hits the floor first).
    pub no_predicted_bounce: usize,
    /// The recording does not reach t_last + horizon (or has a gap there).
    pub ahead_beyond_data: usize,
    /// (a), mm.
    pub bounce: Stats,
    /// (b), mm.
    pub ahead: Stats,
}

/// The whole evaluation: per set in [`SETS`] order (then any other set
/// names), all pooled, and every trajectory's result.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// The horizon of (b), s.
    pub horizon: f64,
    /// One group per set present, in [`SETS`] order, then any other set names.
    pub sets: Vec<GroupReport>,
    /// All sets pooled.
    pub all: GroupReport,
    /// Every trajectory's result, in input order.
    pub results: Vec<TrajectoryResult>,
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for g in self.sets.iter().chain(std::iter::once(&self.all)) {
            writeln!(
                f,
                "{:<14} used {:>2}/{:<2} | bounce xy mm: {} | {:.1}s-ahead 3D mm: {} | skipped: no real bounce {}, no predicted bounce {}, data ends {}, declined {}",
                g.name,
                g.used,
                g.trajectories,
                g.bounce,
                self.horizon,
                g.ahead,
                g.no_real_bounce,
                g.no_predicted_bounce,
                g.ahead_beyond_data,
                g.no_prediction
            )?;
        }
        Ok(())
    }
}

/// The recorded position at `t`, linearly interpolated between the samples
/// around it; `None` outside the recording or across a gap.
pub(crate) fn interpolate(s: &[(f64, Vec3)], t: f64, max_gap: f64) -> Option<Vec3> {
    let k = s.partition_point(|(ts, _)| *ts < t);
    if k == 0 || k >= s.len() {
        return (k < s.len() && s[k].0 == t).then(|| s[k].1);
    }
    let (t0, p0) = s[k - 1];
    let (t1, p1) = s[k];
    if t1 - t0 > max_gap {
        return None;
    }
    let w = (t - t0) / (t1 - t0);
    Some(p0 + (p1 - p0) * w)
}

/// The first table contact of `pred` under `prop`.
pub(crate) fn predicted_bounce(prop: &Propagator, pred: &Prediction, max_flight: f64) -> Option<(f64, Vec3)> {
    let prop = prop.with_scales(pred.scales);
    let mut s = pred.state;
    let mut t = pred.t;
    let stop = StopAt::time(pred.t + max_flight);
    match prop.advance(&mut s, &mut t, &stop) {
        Event::Bounce { t, before } => Some((t, before.pos)),
        _ => None,
    }
}

/// The position of `pred` at `t_end` under `prop`, through bounces.
pub(crate) fn predicted_position(prop: &Propagator, pred: &Prediction, t_end: f64) -> Option<Vec3> {
    let prop = prop.with_scales(pred.scales);
    let mut s = pred.state;
    let mut t = pred.t;
    let stop = StopAt::time(t_end);
    for _ in 0..8 {
        match prop.advance(&mut s, &mut t, &stop) {
            Event::TimeLimit { .. } => return Some(s.pos),
            Event::Bounce { .. } => continue,
            _ => return None,
        }
    }
    None
}

/// The predictor's output for one trajectory (`None` with too few pre-net
/// samples, a declined or a non-finite prediction).
pub(crate) fn predict_one<P: Predictor + ?Sized>(
    tr: &PreparedTrajectory,
    predictor: &P,
    cfg: &EvalConfig,
) -> Option<Prediction> {
    if tr.pre_net < cfg.min_samples {
        return None;
    }
    predictor.predict(&tr.samples[..tr.pre_net]).filter(|p| p.state.is_finite())
}

/// Scores a prediction made from `tr`'s pre-net samples.
pub(crate) fn score_one(tr: &PreparedTrajectory, prediction: Option<Prediction>, cfg: &EvalConfig) -> TrajectoryResult {
    let mut r = TrajectoryResult {
        set: tr.set.clone(),
        index: tr.index,
        samples_used: tr.pre_net,
        prediction: None,
        predicted_bounce: None,
        real_bounce: tr.bounce.map(|b| (b.t, b.pos)),
        bounce_error_mm: None,
        predicted_ahead: None,
        real_ahead: None,
        ahead_error_mm: None,
    };
    if tr.pre_net < cfg.min_samples {
        return r;
    }
    let used = &tr.samples[..tr.pre_net];
    let Some(pred) = prediction.filter(|p| p.state.is_finite()) else {
        return r;
    };
    r.prediction = Some(pred);
    let prop = &cfg.propagator;
    r.predicted_bounce = predicted_bounce(prop, &pred, cfg.max_flight);
    if let (Some((_, p)), Some((_, q))) = (r.predicted_bounce, r.real_bounce) {
        r.bounce_error_mm = Some(1e3 * (p.xy() - q.xy()).norm());
    }
    let t_end = used[used.len() - 1].0 + cfg.horizon;
    r.real_ahead = interpolate(&tr.samples, t_end, cfg.max_interp_gap);
    if r.real_ahead.is_some() {
        r.predicted_ahead = predicted_position(prop, &pred, t_end);
    }
    if let (Some(p), Some(q)) = (r.predicted_ahead, r.real_ahead) {
        r.ahead_error_mm = Some(1e3 * (p - q).norm());
    }
    r
}

/// The predictor's output for every trajectory, in order, spread over the
/// available cores (each trajectory is independent; the result does not
/// depend on the thread count).
pub(crate) fn predict_all<P: Predictor + Sync + ?Sized>(
    trajs: &[PreparedTrajectory],
    predictor: &P,
    cfg: &EvalConfig,
) -> Vec<Option<Prediction>> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).clamp(1, 16);
    if threads == 1 || trajs.len() < 8 {
        return trajs.iter().map(|tr| predict_one(tr, predictor, cfg)).collect();
    }
    let chunk = trajs.len().div_ceil(threads);
    std::thread::scope(|scope| {
        let handles: Vec<_> = trajs
            .chunks(chunk)
            .map(|part| scope.spawn(move || part.iter().map(|tr| predict_one(tr, predictor, cfg)).collect::<Vec<_>>()))
            .collect();
        handles.into_iter().flat_map(|h| h.join().expect("a prediction thread panicked")).collect()
    })
}

fn group(name: &str, results: &[&TrajectoryResult], cfg: &EvalConfig) -> GroupReport {
    let used: Vec<_> = results.iter().filter(|r| r.samples_used >= cfg.min_samples).collect();
    let predicted: Vec<_> = used.iter().filter(|r| r.prediction.is_some()).collect();
    let bounce: Vec<f64> = predicted.iter().filter_map(|r| r.bounce_error_mm).collect();
    let ahead: Vec<f64> = predicted.iter().filter_map(|r| r.ahead_error_mm).collect();
    GroupReport {
        name: name.to_owned(),
        trajectories: results.len(),
        used: used.len(),
        no_prediction: used.len() - predicted.len(),
        no_real_bounce: predicted.iter().filter(|r| r.real_bounce.is_none()).count(),
        no_predicted_bounce: predicted
            .iter()
            .filter(|r| r.real_bounce.is_some() && r.predicted_bounce.is_none())
            .count(),
        ahead_beyond_data: predicted.iter().filter(|r| r.real_ahead.is_none()).count(),
        bounce: Stats::of(&bounce),
        ahead: Stats::of(&ahead),
    }
}

/// Evaluates `predictor` on every trajectory and summarises per set.
pub fn evaluate<P: Predictor + Sync + ?Sized>(trajs: &[PreparedTrajectory], predictor: &P, cfg: &EvalConfig) -> Report {
    evaluate_predictions(trajs, &predict_all(trajs, predictor, cfg), cfg)
}

/// Scores predictions made earlier (`predictions[i]` from `trajs[i]`, as
/// [`predict_all`] returns them) and summarises per set: one fit, several
/// horizons.
pub(crate) fn evaluate_predictions(
    trajs: &[PreparedTrajectory],
    predictions: &[Option<Prediction>],
    cfg: &EvalConfig,
) -> Report {
    let results: Vec<TrajectoryResult> =
        trajs.iter().zip(predictions).map(|(tr, pred)| score_one(tr, *pred, cfg)).collect();
    let mut names: Vec<&str> = SETS.to_vec();
    for r in &results {
        if !names.contains(&r.set.as_str()) {
            names.push(&r.set);
        }
    }
    let sets = names
        .iter()
        .filter_map(|name| {
            let members: Vec<_> = results.iter().filter(|r| r.set == *name).collect();
            (!members.is_empty()).then(|| group(name, &members, cfg))
        })
        .collect();
    let all = group("all", &results.iter().collect::<Vec<_>>(), cfg);
    Report { horizon: cfg.horizon, sets, all, results }
}

#[cfg(test)]
mod tests {
    use super::*;
    use topspin_core::physics::{PhysicsParams, Table};

    fn paper_prop() -> Propagator {
        let p = PhysicsParams::paper();
        Propagator::new(p.flight_model(), p.bounce_model(), Table::default())
    }

    /// A spin-free ball sampled at 180 Hz from the paper's own physics.
    fn synthetic(index: usize) -> PreparedTrajectory {
        let prop = paper_prop();
        let s0 = BallState::new(Vec3::new(-1.3, 0.0, 0.3), Vec3::new(5.0, 0.05 * index as f64, 0.8), Vec3::zeros());
        let samples: Vec<(f64, Vec3)> = (0..140)
            .map(|k| {
                let t = k as f64 / 180.0;
                let pred = Prediction::calibrated(0.0, s0);
                (t, predicted_position(&prop, &pred, t).unwrap())
            })
            .collect();
        let tr = RealTrajectory { set: "no_spin".into(), index, launcher: [0.0; 5], samples };
        let frame = LabToTable { yaw: 0.0, origin: [0.0; 3] };
        prepare([&tr], &frame).remove(0)
    }

    #[test]
    fn baseline_is_near_exact_on_its_own_physics() {
        let trajs: Vec<_> = (0..3).map(synthetic).collect();
        let cfg = EvalConfig::new(paper_prop());
        let rep = evaluate(&trajs, &CubicBaseline, &cfg);
        assert_eq!(rep.all.used, 3);
        assert_eq!(rep.all.bounce.count, 3, "{rep}");
        assert_eq!(rep.all.ahead.count, 3, "{rep}");
        // Only the cubic's model error remains (drag is not a cubic).
        assert!(rep.all.bounce.median < 5.0, "{rep}");
        assert!(rep.all.ahead.median < 10.0, "{rep}");
    }

    #[test]
    fn stats_and_interpolation() {
        let s = Stats::of(&[1.0, 2.0, 3.0, 10.0]);
        assert_eq!((s.count, s.mean, s.median), (4, 4.0, 2.5));
        let pts = [(0.0, Vec3::zeros()), (0.01, Vec3::new(1.0, 0.0, 0.0))];
        assert_eq!(interpolate(&pts, 0.005, 0.02), Some(Vec3::new(0.5, 0.0, 0.0)));
        assert_eq!(interpolate(&pts, 0.02, 0.02), None);
        assert_eq!(interpolate(&pts, 0.005, 0.001), None);
    }
}
