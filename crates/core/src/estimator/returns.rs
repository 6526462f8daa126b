//! The spin the rubber met, read from the return's flight.
//!
//! A real ball's lift saturates and a fast topspin ball's bounce slides,
//! so neither its flight nor the table tells a fast spin from a medium
//! one. The bat does: the ball leaves the rubber with a velocity that
//! turns with the spin it brought (the face tilt a stroke needs moves by
//! 3–4° per tenth of the spin). The tracker follows the return for a few
//! frames after the hit; the velocity it shows, against the planned bat
//! (face and velocity) and the racket contact model, reads the spin the
//! ball brought to the bat, and so the scale of the spin its flight showed
//! before the bounce ([`Watch::read`]). The session keeps it as it keeps the
//! ceiling camera's reading ([`super::spin_prior::SpinPrior::take_read`]):
//! the next alike balls (speed, lift direction) are aimed with it. What
//! the plan does not know of the bat (the arm's tracking of the face and
//! its speed, where on the face the ball met it) is in the reading's
//! uncertainty ([`BAT_VEL_SIGMA`]); a return no spin explains is not read.
//! Fixed memory, bounded work (one reading a ball).

use heapless::Vec as HVec;

use crate::fit::Sample;
use crate::physics::{BallState, BounceModel, FlightModel, RacketModel, Vec3};

/// Samples of the return a reading is made from (the first after the hit).
pub(crate) const RETURN_SAMPLES: usize = 12;
/// Fewest samples a reading is made from.
pub(crate) const RETURN_MIN_SAMPLES: usize = 6;
/// The return is watched this long after the planned hit, s.
pub(crate) const RETURN_WATCH_S: f64 = 0.15;
/// The first return sample must lie within this distance of the planned
/// hitting point, flown back to the hit, m: farther, it is another ball.
const HIT_DISTANCE_M: f64 = 0.10;
/// σ per axis of the velocity the planned bat leaves unexplained, m/s: the
/// arm's tracking of the face (≈ 0.5° at 5 m/s) and of its speed, and the
/// contact off the face's centre.
pub(crate) const BAT_VEL_SIGMA: f64 = 0.12;
/// Least σ of the ln of a reading's scale (the rubber's own constants).
const SCALE_SIGMA_FLOOR: f64 = 0.05;
/// Most σ of the ln of a reading's scale: a return that turns so little
/// with the spin (the ball slid on the rubber) does not tell it.
const SCALE_SIGMA_MAX: f64 = 0.3;
/// Most a reading's normalised squared residual may be (3 axes): above, the
/// bat did not meet the ball as planned, and the return tells nothing.
const CHI2_MAX: f64 = 16.0;
/// The scales tried: ×0.5 to ×4 of the flight's spin in steps of 2^(1/16).
const SCALE_STEPS: usize = 49;

fn scale_step(k: usize) -> f64 {
    0.5 * (k as f64 / 16.0).exp2()
}

/// A stroke as planned: what its return is read against.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Stroke {
    /// The ball's track.
    pub trajectory: u32,
    /// When the bat should meet the ball, s.
    pub t_hit: f64,
    /// Where (the ball's centre), m, and the ball's velocity there, m/s.
    pub pos: Vec3,
    pub vel: Vec3,
    /// The ball at its bounce as its flight showed it (spin in the
    /// flight's reading), and the table it met (`spin_scale` aside).
    pub before_bounce: BallState,
    pub table: BounceModel,
    /// The face's outward normal and the bat's velocity at the hit.
    pub normal: Vec3,
    pub bat_vel: Vec3,
    /// The ball's speed at the first sample of its track, m/s.
    pub speed0: f64,
}

/// A stroke's return being watched: its first samples after the hit.
#[derive(Clone, Debug)]
pub(crate) struct Watch {
    pub stroke: Stroke,
    samples: HVec<Sample, RETURN_SAMPLES>,
}

/// A reading of the spin the ball brought to the bat.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct ReturnRead {
    /// The ball's spin before its bounce per unit of its flight's reading.
    pub(crate) scale: f64,
    /// σ of its ln.
    pub(crate) sigma: f64,
}

impl Watch {
    /// Starts watching the return of `stroke`.
    pub(crate) fn new(stroke: Stroke) -> Self {
        Watch { stroke, samples: HVec::new() }
    }

    /// Takes one sample; true once the watch has all it keeps.
    pub(crate) fn push(&mut self, s: Sample) -> bool {
        if self.samples.last().is_none_or(|l| s.t > l.t) {
            let _ = self.samples.push(s);
        }
        self.samples.is_full()
    }

    /// True once `t` lies past what the watch looks at.
    pub(crate) fn over(&self, t: f64) -> bool {
        t > self.stroke.t_hit + RETURN_WATCH_S
    }

    /// Reads the spin from the samples taken (`sigma`: the tracker's
    /// position noise, m): `None` with too few, where they do not leave
    /// the bat, or where no spin explains them.
    pub(crate) fn read(&self, racket: &RacketModel, flight: &FlightModel, sigma: f64) -> Option<ReturnRead> {
        let st = &self.stroke;
        if self.samples.len() < RETURN_MIN_SAMPLES {
            return None;
        }
        let table = st.table.with_spin_scale(1.0);
        let leaving = |k: f64| {
            let bounced = table.apply(&BallState { spin: st.before_bounce.spin * k, ..st.before_bounce });
            let ball = BallState::new(st.pos, st.vel, bounced.spin);
            racket.hit(&ball, &st.normal, &st.bat_vel).map(|i| i.after)
        };
        // The flight's pull over the few frames watched, as at the return
        // of the spin the flight showed (scale 1), then as at the spin
        // read from it.
        let pull = |k: f64| leaving(k).map(|b| flight.accel(&b.vel, &b.spin));
        let first = scan(&self.samples, st, &leaving, &pull(1.0)?, sigma)?;
        scan(&self.samples, st, &leaving, &pull(first.scale)?, sigma)
    }
}

/// The scale whose return `leaving` best explains `samples` (the flight's
/// pull `accel`, the tracker's noise `sigma`), and its σ.
fn scan(
    samples: &[Sample],
    st: &Stroke,
    leaving: &impl Fn(f64) -> Option<BallState>,
    accel: &Vec3,
    sigma: f64,
) -> Option<ReturnRead> {
    let (pos, vel, var) = fit_line(samples, st.t_hit, accel, sigma)?;
    if vel.x >= 0.0 || (pos - st.pos).norm() > HIT_DISTANCE_M {
        return None;
    }
    let var = var.add_scalar(BAT_VEL_SIGMA * BAT_VEL_SIGMA);
    let cost = |k: f64| {
        leaving(k).map_or(f64::INFINITY, |b| (b.vel - vel).component_mul(&(b.vel - vel)).component_div(&var).sum())
    };
    let costs: [f64; SCALE_STEPS] = std::array::from_fn(|k| cost(scale_step(k)));
    let best = (0..SCALE_STEPS).min_by(|&a, &b| costs[a].total_cmp(&costs[b]))?;
    if best == 0 || best == SCALE_STEPS - 1 || costs[best].is_nan() || costs[best] > CHI2_MAX {
        return None; // bounded on one side only, or unexplained
    }
    // A parabola through the best step and its neighbours, in ln k.
    let (a, b, c) = (costs[best - 1], costs[best], costs[best + 1]);
    let h = (2.0f64).ln() / 16.0;
    let curve = (a - 2.0 * b + c) / (h * h);
    if curve.is_nan() || curve <= 0.0 {
        return None;
    }
    let shift = (0.5 * h * (a - c) / (a - 2.0 * b + c)).clamp(-h, h);
    let scale = scale_step(best) * shift.exp();
    // cost ≈ cost_min + (Δ ln k / σ)²: the curvature is 2/σ².
    let sigma = (2.0 / curve).sqrt().max(SCALE_SIGMA_FLOOR);
    (sigma <= SCALE_SIGMA_MAX).then_some(ReturnRead { scale, sigma })
}

/// The line p(τ) = p₀ + v τ + ½ a τ² (τ = t − `t0`, `a` known) through
/// `samples` by least squares per axis: p₀, v and the variance of v per
/// axis (position noise `sigma`); `None` where the samples span no time
/// or stray from it by more than the noise allows.
fn fit_line(samples: &[Sample], t0: f64, a: &Vec3, sigma: f64) -> Option<(Vec3, Vec3, Vec3)> {
    let n = samples.len() as f64;
    let tau = |s: &Sample| s.t - t0;
    let y = |s: &Sample| s.pos - a * (0.5 * tau(s) * tau(s));
    let t_mean = samples.iter().map(tau).sum::<f64>() / n;
    let y_mean = samples.iter().map(y).sum::<Vec3>() / n;
    let stt = samples.iter().map(|s| (tau(s) - t_mean).powi(2)).sum::<f64>();
    if stt.is_nan() || stt <= 0.0 {
        return None;
    }
    let vel = samples.iter().map(|s| y(s) * (tau(s) - t_mean)).sum::<Vec3>() / stt;
    let pos = y_mean - vel * t_mean;
    let sq = samples.iter().map(|s| (y(s) - pos - vel * tau(s)).norm_squared()).sum::<f64>();
    // Three axes, two parameters each.
    if sq / (3.0 * (n - 2.0)) > (4.0 * sigma).powi(2) {
        return None;
    }
    Some((pos, vel, Vec3::repeat(sigma * sigma / stt)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;
    use crate::physics::{Event, StopAt};

    /// Flies `ball` to time `to` (bounces included).
    fn fly(prop: &crate::physics::Propagator, ball: &mut BallState, t: &mut f64, to: f64) {
        while matches!(prop.advance(ball, t, &StopAt::time(to)), Event::Bounce { .. }) {}
    }

    /// A topspin ball after its bounce, met by a closed face moving at
    /// 0.5 m/s, and the tracker's view of the return (every 1/150 s from
    /// two frames after the hit, noise-free).
    fn stroke_and_return(cal: &Calibration, true_scale: f64) -> (Stroke, Vec<Sample>) {
        let prop = cal.propagator();
        let before = BallState::new(Vec3::new(0.9, 0.05, 0.02), Vec3::new(6.0, 0.1, -2.0), Vec3::new(0.0, 300.0, 0.0));
        let table = prop.bounce.with_spin_scale(1.0);
        let after = table.apply(&BallState { spin: before.spin * true_scale, ..before });
        let (mut ball, mut t) = (after, 0.0);
        ball.pos.z = prop.bounce.radius;
        fly(&prop, &mut ball, &mut t, 0.1);
        let tilt: f64 = -0.4;
        let normal = Vec3::new(-tilt.cos(), 0.0, tilt.sin());
        let bat_vel = normal * 0.5;
        let stroke = Stroke {
            trajectory: 1,
            t_hit: t,
            pos: ball.pos,
            vel: ball.vel,
            before_bounce: before,
            table: prop.bounce,
            normal,
            bat_vel,
            speed0: 6.0,
        };
        let mut out = cal.racket_model().hit(&ball, &normal, &bat_vel).unwrap().after;
        let mut t_out = t;
        let samples = (2..2 + RETURN_SAMPLES)
            .map(|i| {
                let at = t + i as f64 / 150.0;
                fly(&prop, &mut out, &mut t_out, at);
                Sample::new(t_out, out.pos)
            })
            .collect();
        (stroke, samples)
    }

    fn read(cal: &Calibration, stroke: Stroke, samples: &[Sample]) -> Option<ReturnRead> {
        let mut w = Watch::new(stroke);
        for s in samples {
            w.push(*s);
        }
        w.read(&cal.racket_model(), &cal.propagator().flight, 0.002)
    }

    #[test]
    fn the_return_reads_the_spin_the_ball_brought() {
        let cal = Calibration::default_cell();
        for true_scale in [0.7, 1.0, 1.6] {
            let (stroke, samples) = stroke_and_return(&cal, true_scale);
            let r = read(&cal, stroke, &samples).expect("a clean return is read");
            assert!((r.scale / true_scale - 1.0).abs() < 0.03, "{true_scale}: read {r:?}");
            assert!(r.sigma >= SCALE_SIGMA_FLOOR && r.sigma < 0.15, "{r:?}");
        }
        // So much spin that the ball slides on the rubber: the return
        // hardly turns with it, and tells nothing.
        let (stroke, samples) = stroke_and_return(&cal, 2.5);
        assert_eq!(read(&cal, stroke, &samples), None);
    }

    #[test]
    fn too_few_samples_another_ball_or_a_ball_flying_on_are_not_read() {
        let cal = Calibration::default_cell();
        let (stroke, samples) = stroke_and_return(&cal, 1.3);
        assert!(read(&cal, stroke, &samples).is_some());
        assert!(read(&cal, stroke, &samples[..RETURN_MIN_SAMPLES - 1]).is_none());
        let elsewhere: Vec<Sample> =
            samples.iter().map(|s| Sample::new(s.t, s.pos + Vec3::new(0.0, 0.3, 0.0))).collect();
        assert!(read(&cal, stroke, &elsewhere).is_none(), "away from the hit");
        let on: Vec<Sample> =
            samples.iter().map(|s| Sample::new(s.t, stroke.pos + stroke.vel * (s.t - stroke.t_hit))).collect();
        assert!(read(&cal, stroke, &on).is_none(), "the ball flew on");
    }

    #[test]
    fn the_estimator_reads_a_returned_balls_spin_and_keeps_it_once() {
        use crate::estimator::{EndReason, Estimator, EstimatorConfig, EstimatorEvent};
        use crate::time::Instant;
        let cal = Calibration::default_cell();
        let (prop, racket) = (cal.propagator(), cal.racket_model());
        let true_spin = 250.0;
        for returns in [true, false] {
            let mut cfg = EstimatorConfig::default();
            cfg.learn.returns = returns;
            let mut est = Estimator::new(&cal, cfg);
            // A topspin ball seen at 150 Hz until its planned hit.
            let mut ball =
                BallState::new(Vec3::new(-1.6, 0.0, 0.35), Vec3::new(5.5, 0.0, 1.2), Vec3::new(0.0, true_spin, 0.0));
            let (mut t, mut plan) = (0.0, None);
            let mut events = Vec::new();
            while plan.is_none_or(|p: crate::plan::StrikePlan| t < p.hit_time.as_secs_f64()) && t < 2.0 {
                let out = est.observe(Instant::from_secs_f64(t), ball.pos);
                plan = out.plan.or(plan);
                events.extend_from_slice(&out.events);
                let next = t + 1.0 / 150.0;
                fly(&prop, &mut ball, &mut t, next);
            }
            let plan = plan.expect("a plan");
            // The bat meets it as planned; the tracker follows the return.
            let hit = plan.hit_time.as_secs_f64();
            let (mut back, mut t_back) = (ball, t);
            fly(&prop, &mut back, &mut t_back, hit);
            back = racket.hit(&back, &plan.orientation.face_normal(), &plan.velocity).unwrap().after;
            for k in 2..32 {
                fly(&prop, &mut back, &mut t_back, hit + k as f64 / 150.0);
                events.extend_from_slice(&est.observe(Instant::from_secs_f64(t_back), back.pos).events);
            }
            let struck =
                events.iter().filter(|e| matches!(e, EstimatorEvent::Ended { reason: EndReason::Struck, .. })).count();
            let kept = est.session().spin.remembered();
            if returns {
                assert_eq!((struck, est.session().returns_read), (1, 1), "{events:?}");
                // Kept once, read, at the spin it flew with (the flight's
                // spin off its axis by a few degrees counts in its size).
                let [(_, spin, read)] = kept[..] else { panic!("{kept:?}") };
                assert!(read && (spin / true_spin - 1.0).abs() < 0.08, "{kept:?}");
            } else {
                assert_eq!((struck, est.session().returns_read), (0, 0));
                assert!(kept.iter().all(|k| !k.2), "{kept:?}");
            }
        }
    }
}
