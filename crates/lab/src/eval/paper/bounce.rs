//! Table III of the paper: the bounce-point error per launcher setting with
//! the fitted spin and without spin. The paper's "without spin" is a Kalman
//! filter on position and velocity; ours is the same: the EKF of
//! [`topspin_core::estimator::Ekf`] with the spin state pinned at zero (no prior
//! variance, no random walk), fed every observation before the net.
//!
//! Each simulated ball is predicted from its observations before the net
//! (the robot's real case: it must move before the bounce) and the first
//! predicted table contact is compared with the true one (xy distance).

use rayon::prelude::*;
use serde::Serialize;

use super::{PaperConfig, Progress, ball_index};
use crate::data::eval::{Prediction, Predictor, predicted_bounce};
use crate::data::spin::FitPredictor;
use topspin_core::calib::Calibration;
use topspin_core::estimator::{Ekf, EkfNoise};
use topspin_core::physics::{BallState, Propagator, Vec3};
use topspin_core::stats::Summary;
use topspin_sim::{Setting, SimBall, simulate_ball};

/// The paper's Table III: (with fitted spin: mean, std; without: mean, std), mm.
pub(crate) const PAPER_TABLE_III: [[f64; 4]; 9] = [
    [10.28, 5.09, 36.78, 6.57],
    [27.02, 11.22, 125.76, 17.08],
    [43.37, 32.14, 170.75, 25.15],
    [9.68, 5.56, 43.15, 7.99],
    [16.35, 10.47, 82.74, 13.82],
    [27.99, 9.80, 108.24, 11.23],
    [19.01, 5.62, 90.10, 16.96],
    [23.36, 11.24, 167.17, 14.76],
    [86.84, 52.70, 338.28, 31.00],
];

/// The predictors of the table, in column order.
pub const PREDICTORS: [&str; 4] = ["paper fit", "refined fit", "Kalman, no spin", "refined, spin 0"];

/// Samples used to start the Kalman filter (a line per axis).
pub(crate) const KF_START: usize = 5;

/// White acceleration noise of the spin-free Kalman filter, (m/s²)²·s: it
/// must absorb the Magnus force its model lacks (up to ~20 m/s²). Swept
/// over 0.005 (the spin EKF's), 1, 10, 100, 1000 on 36 simulated balls
/// and the real recordings: 10 is near the best on both (median bounce
/// error 131 mm simulated, 20 mm real); 0.005 lets the gate reject the
/// track and drift (385 mm).
pub(crate) const KF_ACCEL_NOISE: f64 = 10.0;

/// A Kalman filter on position and velocity only (the paper's comparison):
/// started from a straight line through the first [`KF_START`] samples,
/// then one predict/update per sample; the spin stays zero.
#[derive(Copy, Clone, Debug)]
pub(crate) struct KalmanNoSpin {
    pub propagator: Propagator,
    /// Per-axis measurement σ, m.
    pub noise: f64,
}

impl Predictor for KalmanNoSpin {
    fn predict(&self, samples: &[(f64, Vec3)]) -> Option<Prediction> {
        if samples.len() < KF_START + 2 {
            return None;
        }
        let head = &samples[..KF_START];
        let tm = head.iter().map(|s| s.0).sum::<f64>() / KF_START as f64;
        let pm = head.iter().map(|s| s.1).sum::<Vec3>() / KF_START as f64;
        let stt: f64 = head.iter().map(|s| (s.0 - tm).powi(2)).sum();
        if stt <= 0.0 {
            return None;
        }
        let vel = head.iter().map(|s| (s.1 - pm) * (s.0 - tm)).sum::<Vec3>() / stt;
        let (t0, _) = head[KF_START - 1];
        let state = BallState::new(pm + vel * (t0 - tm), vel, Vec3::zeros());
        let noise = EkfNoise {
            measurement: self.noise,
            accel: KF_ACCEL_NOISE,
            spin: 0.0,
            bounce_spin: 0.0,
            ..EkfNoise::default()
        };
        let mut ekf = Ekf::new(t0, &state, 3.0 * self.noise, 1.0, 0.0, noise);
        for (t, p) in &samples[KF_START..] {
            // Pre-net samples hold no bounce; the returned bounce time is moot.
            let _ = ekf.predict(&self.propagator, *t);
            ekf.update(p);
        }
        let state = ekf.state();
        state.is_finite().then_some(Prediction::calibrated(ekf.t, state))
    }
}

/// One ball's bounce errors (mm) per predictor; `None` where a predictor
/// gave no bounce.
#[derive(Clone, Debug, Serialize)]
pub struct BallBounce {
    /// The launcher setting.
    pub setting: Setting,
    /// The ball's index in the run.
    pub ball: usize,
    /// Bounce-point error (xy) per predictor of [`PREDICTORS`], mm; `None`
    /// where it gave no bounce.
    pub errors_mm: [Option<f64>; 4],
}

/// One row of Table III.
#[derive(Clone, Debug, Serialize)]
pub struct BounceRow {
    /// The launcher setting.
    pub setting: Setting,
    /// Per predictor ([`PREDICTORS`]).
    pub ours: [Summary; 4],
    /// The paper's (with spin mean, std, without mean, std).
    pub paper: [f64; 4],
}

/// The table and the balls behind it.
#[derive(Clone, Debug, Serialize)]
pub struct BounceTable {
    /// One row per launcher setting, in `Setting::ALL` order.
    pub rows: Vec<BounceRow>,
    /// Per predictor, over the balls of every setting, mm.
    pub all: [Summary; 4],
    /// Every ball's errors.
    pub balls: Vec<BallBounce>,
}

/// The observations before the true net crossing, as (t, position).
pub(crate) fn pre_net(ball: &SimBall) -> Vec<(f64, Vec3)> {
    let end = ball.truth.net_crossing_t.unwrap_or(f64::INFINITY);
    ball.observations.iter().filter(|o| o.t < end && !o.outlier).map(|o| (o.t, o.pos)).collect()
}

/// The four predictors under `cal`'s physics at tracker noise `noise` (m).
pub(crate) fn predictors(cal: &Calibration, noise: f64) -> [Box<dyn Predictor + Sync>; 4] {
    let p = &cal.physics;
    [
        Box::new(FitPredictor::paper(p).with_noise(noise)),
        Box::new(FitPredictor::refined(p).with_noise(noise)),
        Box::new(KalmanNoSpin { propagator: cal.propagator(), noise }),
        Box::new(FitPredictor::no_spin(p).with_noise(noise)),
    ]
}

fn ball_errors(cal: &Calibration, preds: &[Box<dyn Predictor + Sync>; 4], ball: &SimBall) -> [Option<f64>; 4] {
    let prop = cal.propagator();
    let samples = pre_net(ball);
    let Some(tb) = ball.truth.bounce.as_ref() else { return [None; 4] };
    let truth = Vec3::from(tb.pos).xy();
    std::array::from_fn(|i| {
        let pred = preds[i].predict(&samples)?;
        let (_, pos) = predicted_bounce(&prop, &pred, 2.0)?;
        Some((pos.xy() - truth).norm() * 1e3)
    })
}

/// Runs Table III: `cfg.bounce_balls` balls per setting.
pub fn table(cal: &Calibration, cfg: &PaperConfig, progress: &dyn Progress) -> BounceTable {
    let prop = cal.propagator();
    let tracker = cfg.tracker();
    let preds = predictors(cal, cfg.noise_mm * 1e-3);
    let jobs: Vec<(usize, usize)> =
        (0..Setting::ALL.len()).flat_map(|i| (0..cfg.bounce_balls).map(move |j| (i, j))).collect();
    progress.stage("Table III: bounce prediction", jobs.len() as u64);
    let balls: Vec<BallBounce> = jobs
        .par_iter()
        .filter_map(|&(i, j)| {
            let setting = Setting::ALL[i];
            let k = ball_index(i, j);
            let ball = simulate_ball(cfg.seed, k, setting, &prop, cal.strike.hit_plane_x, &tracker).ok();
            let out = ball.map(|b| BallBounce { setting, ball: k, errors_mm: ball_errors(cal, &preds, &b) });
            progress.inc(1);
            out
        })
        .collect();
    let summarise = |sel: &dyn Fn(&BallBounce) -> bool| -> [Summary; 4] {
        std::array::from_fn(|c| {
            let v: Vec<f64> = balls.iter().filter(|b| sel(b)).filter_map(|b| b.errors_mm[c]).collect();
            Summary::of(&v)
        })
    };
    let rows = Setting::ALL
        .iter()
        .zip(PAPER_TABLE_III)
        .map(|(s, paper)| BounceRow { setting: *s, ours: summarise(&|b| b.setting == *s), paper })
        .collect();
    BounceTable { rows, all: summarise(&|_| true), balls }
}

#[cfg(test)]
mod tests {
    use super::*;
    use topspin_sim::TrackerModel;

    #[test]
    fn kalman_without_spin_tracks_a_spin_free_ball() {
        // A backspin ball's pre-net track: the spin-free filter misses its
        // bounce by centimetres, the refined fit by millimetres.
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let tracker = TrackerModel { noise_sigma: 0.001, ..TrackerModel::default() };
        let ball = simulate_ball(3, 1, Setting::ALL[1], &prop, cal.strike.hit_plane_x, &tracker).unwrap();
        let e = ball_errors(&cal, &predictors(&cal, 0.001), &ball);
        let (refined, kalman) = (e[1].unwrap(), e[2].unwrap());
        assert!(refined < 20.0, "{e:?}");
        assert!(kalman > 2.0 * refined, "{e:?}");
    }
}
