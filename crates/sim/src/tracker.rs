//! The multi-camera tracker as the daemon sees it: samples of the true
//! ball position at a fixed rate with a random phase, Gaussian noise per
//! axis, random dropouts, and false detections at the start of a flight (a
//! hand near the launcher, as in the paper's §IV). Every false detection is
//! labelled `outlier: true`, so evaluation can check the filter. Sampling
//! runs from launch until the flight's end (the hitting plane, or the
//! floor). Deterministic in the rng it is given.

use rand::Rng;
use rand_distr::StandardNormal;

use super::truth::{Flight, Truth};
use topspin_core::physics::{Propagator, Vec3};

/// How the tracker sees the ball.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct TrackerModel {
    /// Frame rate, Hz (> 0).
    pub rate_hz: f64,
    /// Standard deviation of the position noise, m, per axis (≥ 0).
    pub noise_sigma: f64,
    /// Probability that a frame's ball is lost, in [0, 1).
    pub dropout: f64,
    /// False detections at the start of a flight: the first this many
    /// frames see a hand 3–20 cm from the ball instead of the ball.
    pub false_starts: usize,
    /// Capture-to-arrival latency, s (pacing of the live stream only).
    pub latency: f64,
    /// Frames after the flight's end still reported, s.
    pub end_after: f64,
    /// The ball is followed back after the robot's stroke, as a real
    /// cell's cameras see it (the virtual cell and the loopback demo find
    /// each contact on the bat's path and send the return's frames).
    pub follows_returns: bool,
}

impl Default for TrackerModel {
    fn default() -> Self {
        TrackerModel {
            rate_hz: 150.0,
            noise_sigma: 0.002,
            dropout: 0.0,
            false_starts: 0,
            latency: 0.005,
            end_after: 0.0,
            follows_returns: true,
        }
    }
}

/// Distance of a false detection from the ball, m.
pub(crate) const FALSE_START_DISTANCE: (f64, f64) = (0.03, 0.20);

/// One simulated observation.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SimObservation {
    /// Capture time, s (from the ball's launch plus the caller's offset).
    pub t: f64,
    /// Reported position, m, table frame.
    pub pos: Vec3,
    /// True for a false detection (not the ball).
    pub outlier: bool,
}

/// A random unit vector (uniform on the sphere).
fn unit(rng: &mut impl Rng) -> Vec3 {
    loop {
        let v = Vec3::new(rng.sample(StandardNormal), rng.sample(StandardNormal), rng.sample(StandardNormal));
        let n = v.norm();
        if n > 1e-6 {
            return v / n;
        }
    }
}

/// The tracker's observations of the flight `truth` (followed with
/// `prop`), with capture times shifted by `t_offset`. The first frame falls
/// at a uniformly random phase within one frame period after launch.
pub fn observe(
    truth: &Truth,
    prop: &Propagator,
    model: &TrackerModel,
    t_offset: f64,
    rng: &mut impl Rng,
) -> Vec<SimObservation> {
    let mut out = Vec::new();
    if !(model.rate_hz.is_finite() && model.rate_hz > 0.0) {
        return out;
    }
    let launch = truth.to_launch();
    let mut flight = Flight::new(&launch, prop);
    let period = 1.0 / model.rate_hz;
    let phase = rng.random::<f64>() * period;
    let end = truth.end_t + model.end_after.max(0.0);
    let sigma = if model.noise_sigma.is_finite() { model.noise_sigma.max(0.0) } else { 0.0 };
    let mut frame = 0usize;
    loop {
        let t = phase + frame as f64 * period;
        if t > end {
            break;
        }
        let ball = flight.at(t).pos;
        // Draw everything every frame so one option does not shift the
        // random stream of the others' frames more than it must.
        let noise = Vec3::new(
            rng.sample::<f64, _>(StandardNormal),
            rng.sample::<f64, _>(StandardNormal),
            rng.sample::<f64, _>(StandardNormal),
        ) * sigma;
        let lost = rng.random::<f64>() < model.dropout;
        if frame < model.false_starts {
            let (lo, hi) = FALSE_START_DISTANCE;
            let d = lo + (hi - lo) * rng.random::<f64>();
            out.push(SimObservation { t: t + t_offset, pos: ball + unit(rng) * d + noise, outlier: true });
        } else if !lost {
            out.push(SimObservation { t: t + t_offset, pos: ball + noise, outlier: false });
        }
        frame += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::launcher::{Setting, launch};
    use crate::truth::true_position_at;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use topspin_core::calib::Calibration;

    fn truth(k: usize) -> (Truth, Propagator) {
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let mut rng = ChaCha8Rng::seed_from_u64(100 + k as u64);
        let l = launch(Setting::ALL[k % 9], &prop, cal.strike.hit_plane_x, &mut rng).unwrap();
        (Truth::compute(&l, &prop, cal.strike.hit_plane_x), prop)
    }

    #[test]
    fn noise_has_the_asked_spread_and_sampling_covers_the_flight() {
        let model = TrackerModel { noise_sigma: 0.002, ..TrackerModel::default() };
        let mut sum2 = [0.0; 3];
        let mut n = 0usize;
        for k in 0..9 {
            let (truth, prop) = truth(k);
            let mut rng = ChaCha8Rng::seed_from_u64(k as u64);
            let obs = observe(&truth, &prop, &model, 0.0, &mut rng);
            let first = obs[0].t;
            let last = obs.last().unwrap().t;
            assert!((0.0..1.0 / 150.0).contains(&first));
            assert!(last <= truth.end_t && truth.end_t - last < 1.0 / 150.0);
            for w in obs.windows(2) {
                assert!((w[1].t - w[0].t - 1.0 / 150.0).abs() < 1e-9);
            }
            for o in &obs {
                assert!(!o.outlier);
                let e = o.pos - true_position_at(&truth.to_launch(), &prop, o.t);
                for i in 0..3 {
                    sum2[i] += e[i] * e[i];
                }
                n += 1;
            }
        }
        for s in sum2 {
            let sd = (s / n as f64).sqrt();
            assert!((sd - 0.002).abs() < 0.0002, "std {sd} over {n}");
        }
    }

    #[test]
    fn false_starts_come_first_and_are_labelled() {
        let model = TrackerModel { false_starts: 3, dropout: 0.2, ..TrackerModel::default() };
        let (truth, prop) = truth(4);
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let obs = observe(&truth, &prop, &model, 0.0, &mut rng);
        assert!(obs[..3].iter().all(|o| o.outlier));
        assert!(obs[3..].iter().all(|o| !o.outlier));
        for o in &obs[..3] {
            let d = (o.pos - true_position_at(&truth.to_launch(), &prop, o.t)).norm();
            assert!((0.02..0.21).contains(&d), "false start {d} m from the ball");
        }
        // Dropout thins the real samples.
        let full = observe(&truth, &prop, &TrackerModel::default(), 0.0, &mut ChaCha8Rng::seed_from_u64(9));
        let real = obs.len() - 3;
        assert!(real < full.len() - 3 && real as f64 > 0.6 * full.len() as f64);
    }

    #[test]
    fn deterministic_and_offset() {
        let (truth, prop) = truth(2);
        let m = TrackerModel::default();
        let a = observe(&truth, &prop, &m, 0.0, &mut ChaCha8Rng::seed_from_u64(5));
        let b = observe(&truth, &prop, &m, 10.0, &mut ChaCha8Rng::seed_from_u64(5));
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.pos, y.pos);
            assert!((y.t - x.t - 10.0).abs() < 1e-9);
        }
    }
}
