//! `topspin fit stream FILE`: the streaming estimator over a recording of
//! many balls, one line (or JSON object) per ball with its last plan.

use serde_json::json;

use super::BadInput;
use topspin_core::calib::Calibration;
use topspin_core::estimator::{Estimator, EstimatorConfig, EstimatorEvent};
use topspin_core::fit::Sample;
use topspin_core::physics::rad_to_rps;
use topspin_core::plan::StrikePlan;
use topspin_core::time::Instant;

/// One ball as the estimator saw it.
#[derive(Debug)]
struct Ball {
    trajectory: u32,
    started: f64,
    ended: Option<f64>,
    plans: usize,
    last: Option<StrikePlan>,
}

/// Replays `samples` through the estimator of `cal`: where it would meet
/// each ball (its hitting volume, within the arm's reach), or with
/// `plane` on the plane x = `plane` alone, whether or not the arm reaches
/// it (a question about the ball: where and when it crosses there).
pub fn run(
    samples: &[Sample],
    cal: &Calibration,
    plane: Option<f64>,
    noise: f64,
    json_out: bool,
) -> anyhow::Result<()> {
    if let Some(row) = samples.windows(2).position(|w| w[1].t < w[0].t) {
        return Err(BadInput(format!("data row {}: time goes backwards", row + 1)).into());
    }
    let mut cal = cal.clone();
    let mut cfg = EstimatorConfig::default().with_noise(noise);
    if let Some(x) = plane {
        cal.strike = cal.strike.plane_alone(x);
        cfg.arm_reach = false;
    }
    let mut est = Estimator::new(&cal, cfg);
    let mut balls: Vec<Ball> = Vec::new();
    for s in samples {
        // Recording times may start at 0; the estimator only needs them monotonic.
        let out = est.observe(Instant::from_secs_f64(s.t + 1.0), s.pos);
        for e in &out.events {
            match *e {
                EstimatorEvent::Started { trajectory, t, .. } => {
                    balls.push(Ball { trajectory, started: t - 1.0, ended: None, plans: 0, last: None })
                }
                EstimatorEvent::Ended { trajectory, t, .. } => {
                    if let Some(b) = balls.iter_mut().find(|b| b.trajectory == trajectory) {
                        b.ended = Some(t - 1.0);
                    }
                }
                _ => {}
            }
        }
        if let Some(p) = out.plan
            && let Some(b) = balls.iter_mut().find(|b| b.trajectory == p.trajectory)
        {
            b.plans += 1;
            b.last = Some(p);
        }
    }
    if json_out {
        let rows: Vec<_> = balls
            .iter()
            .map(|b| {
                json!({
                    "trajectory": b.trajectory,
                    "start_t": b.started,
                    "end_t": b.ended,
                    "plans": b.plans,
                    "plan": b.last.map(|p| json!({
                        "hit_t": p.hit_time.as_secs_f64() - 1.0,
                        "position": [p.position.x, p.position.y, p.position.z],
                        "velocity": [p.velocity.x, p.velocity.y, p.velocity.z],
                        "orientation_deg": [p.orientation.a.to_degrees(), p.orientation.b.to_degrees(), p.orientation.c.to_degrees()],
                        "spin": [p.spin.x, p.spin.y, p.spin.z],
                        "confidence": p.confidence,
                    })),
                })
            })
            .collect();
        println!("{}", serde_json::Value::Array(rows));
        return Ok(());
    }
    println!("ball  start s  plans  hit t s   hit x m  hit y m  hit z m  spin rps (x, y, z)      β deg  confidence");
    for b in &balls {
        match b.last {
            Some(p) => {
                let w = p.spin.map(rad_to_rps);
                println!(
                    "{:4}  {:7.3}  {:5}  {:7.3}  {:7.3}  {:7.3}  {:7.3}  ({:5.1}, {:5.1}, {:5.1})  {:6.1}  {:.2}",
                    b.trajectory,
                    b.started,
                    b.plans,
                    p.hit_time.as_secs_f64() - 1.0,
                    p.position.x,
                    p.position.y,
                    p.position.z,
                    w.x,
                    w.y,
                    w.z,
                    p.orientation.b.to_degrees(),
                    p.confidence
                );
            }
            None => println!(
                "{:4}  {:7.3}  {:5}  no plan (hit outside the window or never predicted)",
                b.trajectory, b.started, 0
            ),
        }
    }
    Ok(())
}
