//! A synthetic strike-plan stream, as the estimator publishes it: a ball
//! every second; its plan refined every 4 ms from 0.6 s before the hit
//! until 80 ms before it, converging on the final pose and time, then
//! committed. Seeded; the RSI tests drive the session with it over UDP
//! (`tests/rsi_loopback.rs`) and on the virtual clock
//! (`crates/sim/tests/rsi_pair.rs`).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use topspin_core::physics::Vec3;
use topspin_core::plan::{EulerZyx, StrikePlan};
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
