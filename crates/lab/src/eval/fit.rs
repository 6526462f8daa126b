//! Accuracy of the batch spin fit on simulated launcher balls:
//! for each tracker noise, each observation window (up to just before the
//! bounce; up to the net) and each method (the paper's, ours refined), the
//! spin error ‖ω̂ − ω‖/‖ω‖, the bounce-point error and the hitting-point
//! error against ground truth; and the start-outlier experiment.

use serde::Serialize;

use topspin_core::calib::Calibration;
use topspin_core::fit::{FitConfig, Method, Sample, fit_trajectory};
use topspin_core::physics::Vec3;
use topspin_core::stats::Summary;
use topspin_sim::simulate_set;
use topspin_sim::{SimBall, TrackerModel};

/// Which observations the fit sees.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Window {
    /// All observations before the true bounce.
    PreBounce,
    /// All observations before the true net crossing (the robot's real case).
    PreNet,
}

/// Errors of one method on one set.
#[derive(Clone, Debug, Serialize)]
pub struct MethodRow {
    /// Tracker noise σ per axis, mm.
    pub noise_mm: f64,
    /// The observations the fit saw.
    pub window: Window,
    /// The fit method (`paper` or `refined`).
    pub method: &'static str,
    /// ‖ω̂ − ω‖/‖ω‖ in percent.
    pub spin_err_pct: Summary,
    /// Predicted vs true bounce point (x, y), mm.
    pub bounce_err_mm: Summary,
    /// Predicted vs true crossing of the hitting plane (3D), mm, over the
    /// balls whose true crossing lies in the hitting window (the others,
    /// off the table's end below its surface or out of reach, are no
    /// stroke's: not scored).
    pub hit_err_mm: Summary,
    /// Predicted vs true hitting time, ms, over the same balls.
    pub hit_dt_ms: Summary,
    /// Balls the fit failed on or predicted no bounce for, or no hit where
    /// the true hit is in the hitting window.
    pub failures: usize,
}

/// The start-outlier experiment.
#[derive(Clone, Debug, Serialize)]
pub struct OutlierRow {
    /// Tracker noise σ per axis, mm.
    pub noise_mm: f64,
    /// False detections at the start of each ball of the dirty set.
    pub false_starts: usize,
    /// Share of balls whose `outliers` name exactly the false detections.
    pub named_exactly: f64,
    /// Share of balls with every false detection among `outliers`.
    pub all_found: f64,
    /// Median spin error ‖ω̂ − ω‖/‖ω‖ without the false detections, percent.
    pub spin_err_clean_pct: f64,
    /// Median spin error with them, percent.
    pub spin_err_dirty_pct: f64,
    /// Median dirty over median clean spin error.
    pub ratio: f64,
}

/// The method's name in tables and JSON (`paper`, `refined`).
pub fn method_name(m: Method) -> &'static str {
    match m {
        Method::Paper => "paper",
        Method::Refined => "refined",
    }
}

fn v3(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

/// The observations of `ball` inside `window` (its times are from launch).
pub(crate) fn windowed(ball: &SimBall, window: Window) -> Vec<Sample> {
    let end = match window {
        Window::PreBounce => ball.truth.bounce.as_ref().map_or(f64::INFINITY, |b| b.t),
        Window::PreNet => ball.truth.net_crossing_t.unwrap_or(f64::INFINITY),
    };
    ball.observations.iter().filter(|o| o.t < end).map(|o| Sample::new(o.t, o.pos)).collect()
}

/// Errors of one fit of one ball: (spin %, bounce mm), and (hit mm, hit
/// ms) where the true hit lies in the hitting window.
type BallErrors = ([f64; 2], Option<[f64; 2]>);

fn errors(ball: &SimBall, samples: &[Sample], cal: &Calibration, cfg: &FitConfig) -> Option<BallErrors> {
    let fit = fit_trajectory(samples, &cal.propagator(), cfg).ok()?;
    let truth = &ball.truth;
    let spin = v3(truth.spin);
    let spin_err = (fit.spin - spin).norm() / spin.norm() * 100.0;
    let tb = truth.bounce.as_ref()?;
    let pb = fit.prediction.bounce?;
    let bounce_err = (pb.pos.xy() - v3(tb.pos).xy()).norm() * 1e3;
    if !topspin_sim::demo::reachable(cal, ball) {
        return Some(([spin_err, bounce_err], None));
    }
    let th = truth.hit.as_ref()?;
    let ph = fit.prediction.hit?;
    let hit_err = (ph.state.pos - v3(th.pos)).norm() * 1e3;
    let hit_dt = (ph.t - th.t).abs() * 1e3;
    Some(([spin_err, bounce_err], Some([hit_err, hit_dt])))
}

/// One row per (window, method) for `balls` at `noise`.
pub fn accuracy(cal: &Calibration, balls: &[SimBall], noise: f64) -> Vec<MethodRow> {
    let mut rows = Vec::new();
    for window in [Window::PreBounce, Window::PreNet] {
        for method in [Method::Paper, Method::Refined] {
            let cfg =
                FitConfig::new(method, cal.strike.hit_plane_x).with_noise(noise).with_variation(cal.physics.variation);
            let mut cols: [Vec<f64>; 4] = Default::default();
            let mut failures = 0;
            for ball in balls {
                match errors(ball, &windowed(ball, window), cal, &cfg) {
                    Some((e, hit)) => {
                        (0..2).for_each(|k| cols[k].push(e[k]));
                        hit.into_iter().for_each(|h| (0..2).for_each(|k| cols[2 + k].push(h[k])));
                    }
                    None => failures += 1,
                }
            }
            rows.push(MethodRow {
                noise_mm: noise * 1e3,
                window,
                method: method_name(method),
                spin_err_pct: Summary::of(&cols[0]),
                bounce_err_mm: Summary::of(&cols[1]),
                hit_err_mm: Summary::of(&cols[2]),
                hit_dt_ms: Summary::of(&cols[3]),
                failures,
            });
        }
    }
    rows
}

/// Fits the same balls with and without `false_starts` false detections
/// (pre-bounce window, refined fit).
pub fn outlier_experiment(cal: &Calibration, seed: u64, n: usize, noise: f64, false_starts: usize) -> OutlierRow {
    let clean_tracker = TrackerModel { noise_sigma: noise, ..TrackerModel::default() };
    let dirty_tracker = TrackerModel { false_starts, ..clean_tracker };
    let clean = simulate_set(cal, seed, n, &clean_tracker);
    let dirty = simulate_set(cal, seed, n, &dirty_tracker);
    let cfg =
        FitConfig::new(Method::Refined, cal.strike.hit_plane_x).with_noise(noise).with_variation(cal.physics.variation);
    let prop = cal.propagator();
    let (mut exact, mut found, mut total) = (0usize, 0usize, 0usize);
    let (mut e_clean, mut e_dirty) = (Vec::new(), Vec::new());
    for (c, d) in clean.iter().zip(&dirty) {
        let spin = v3(c.truth.spin);
        let samples = windowed(d, Window::PreBounce);
        let (Ok(fc), Ok(fd)) =
            (fit_trajectory(&windowed(c, Window::PreBounce), &prop, &cfg), fit_trajectory(&samples, &prop, &cfg))
        else {
            continue;
        };
        total += 1;
        let truth_rows = d.outlier_rows();
        exact += (fd.outliers == truth_rows) as usize;
        found += truth_rows.iter().all(|r| fd.outliers.contains(r)) as usize;
        e_clean.push((fc.spin - spin).norm() / spin.norm() * 100.0);
        e_dirty.push((fd.spin - spin).norm() / spin.norm() * 100.0);
    }
    let (mc, md) = (Summary::of(&e_clean).median, Summary::of(&e_dirty).median);
    OutlierRow {
        noise_mm: noise * 1e3,
        false_starts,
        named_exactly: exact as f64 / total.max(1) as f64,
        all_found: found as f64 / total.max(1) as f64,
        spin_err_clean_pct: mc,
        spin_err_dirty_pct: md,
        ratio: md / mc,
    }
}
