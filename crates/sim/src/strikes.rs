//! A synthetic strike-plan stream, as the estimator publishes it: a ball
//! every second; its plan refined every 4 ms from 0.6 s before the hit
//! until 80 ms before it, converging on the final pose and time, then
//! committed. Seeded; [`StrikeMiss`] measures how the robot met each
//! committed plan. The RSI tests drive the session with it over UDP
//! (`crates/sim/tests/rsi_loopback.rs`) and on the virtual clock
//! (`crates/sim/tests/rsi_pair.rs`).

use crate::mock_krc::PathSample;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use topspin_core::geometry::EulerZyx;
use topspin_core::motion::MotionLimits;
use topspin_core::physics::Vec3;
use topspin_core::plan::StrikePlan;
use topspin_core::time::{Duration, Instant};

/// One plan of the stream, to publish at its `made_at`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Refinement {
    /// The plan (`made_at`: when to publish it).
    pub plan: StrikePlan,
    /// The ball's last plan: the stroke the robot commits to.
    pub committed: bool,
}

/// The stream from `start` until `end`, seeded with `seed`, in order.
pub fn strike_stream(seed: u64, start: Instant, end: Instant) -> Vec<Refinement> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::new();
    let (mut seq, mut ball) = (0u32, 0u32);
    let mut t_ball = start + Duration::from_millis(400);
    while t_ball + Duration::from_millis(1000) < end {
        ball += 1;
        let hit_time = t_ball + Duration::from_millis(600);
        let fin = StrikePlan {
            seq: 0,
            trajectory: ball,
            made_at: t_ball,
            hit_time,
            position: Vec3::new(1.60, rng.random_range(-0.45..0.45), rng.random_range(0.15..0.45)),
            velocity: Vec3::new(-1.0, rng.random_range(-0.2..0.2), rng.random_range(-0.1..0.3)),
            orientation: EulerZyx {
                a: rng.random_range(-0.2..0.2),
                b: rng.random_range(-0.6..0.45),
                c: rng.random_range(-0.2..0.2),
            },
            spin: Vec3::zeros(),
            confidence: 0.5,
        };
        let noise =
            Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) * 0.04;
        let commit = hit_time.0 - 80_000_000;
        let mut t = t_ball;
        loop {
            seq += 1;
            let left = commit.saturating_sub(t.0) as f64 / (commit - t_ball.0) as f64;
            let mut p = fin;
            p.seq = seq;
            p.made_at = t;
            p.position += noise * left;
            p.hit_time = Instant(hit_time.0 + (left * 3e6) as u64);
            if t.0 >= commit {
                p.hit_time = hit_time;
                p.position = fin.position;
                out.push(Refinement { plan: p, committed: true });
                break;
            }
            out.push(Refinement { plan: p, committed: false });
            t = t + Duration::from_millis(4);
        }
        t_ball = t_ball + Duration::from_millis(1000);
    }
    out
}

/// How far the robot's actual TCP (`path`, the controller's log) was from a
/// committed plan's hitting pose.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct StrikeMiss {
    /// Closest position to the hitting point within ±2 ms of the hit time, mm.
    pub best_mm: f64,
    /// Position error at the hit time, mm.
    pub at_hit_mm: f64,
    /// Largest orientation error (A, B, C) at the hit time, degrees.
    pub rot_deg: f64,
}

impl StrikeMiss {
    /// The miss of `plan` by the path (mm / deg, BASE), the actual pose
    /// interpolated between samples; `lim` converts the plan to BASE.
    pub fn of(path: &[PathSample], plan: &StrikePlan, lim: &MotionLimits) -> StrikeMiss {
        let at = |t: f64| -> [f64; 6] {
            let k = path.partition_point(|s| s.t.as_secs_f64() < t).clamp(1, path.len() - 1);
            let (a, b) = (&path[k - 1], &path[k]);
            let f = (t - a.t.as_secs_f64()) / (b.t.as_secs_f64() - a.t.as_secs_f64());
            std::array::from_fn(|i| a.actual[i] + f * (b.actual[i] - a.actual[i]))
        };
        let target = lim.point_t_to_b(plan.position) * 1e3;
        let abc = lim.orientation_t_to_b(plan.orientation).map(f64::to_degrees);
        let th = plan.hit_time.as_secs_f64();
        let dist =
            |q: [f64; 6]| ((q[0] - target.x).powi(2) + (q[1] - target.y).powi(2) + (q[2] - target.z).powi(2)).sqrt();
        let best_mm = (-20..=20).map(|j| dist(at(th + j as f64 * 1e-4))).fold(f64::INFINITY, f64::min);
        let q = at(th);
        let rot_deg = (0..3).map(|i| (q[3 + i] - abc[i]).abs()).fold(0.0, f64::max);
        StrikeMiss { best_mm, at_hit_mm: dist(q), rot_deg }
    }
}
