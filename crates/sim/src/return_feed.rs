//! The tracker's view of each return in the virtual cell: a real cell's
//! cameras follow the ball back over the table after the robot's stroke,
//! and the estimator reads from it the spin the ball brought to the bat
//! (`topspin_core::estimator`, its `returns` module).
//!
//! Once a ball's stroke is past (its true crossing of the hitting plane
//! and [`JUDGE_AFTER_S`]), the ball leaving the bat is found on the bat's
//! actual path so far exactly as the judge finds it ([`judge_return`]),
//! flown with the ball's own physics, and seen as the tracker sees a
//! flight (its frame rate, noise and dropouts) for [`RETURN_SEEN_S`] after
//! the contact. Frames the stroke's judging time has already passed are not
//! sent (the bat and the arm hide the ball there); the sequence numbers
//! continue the ball's own ([`return_seq`]).

use std::collections::VecDeque;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::faults::{Planned, observation, return_seq};
use crate::mock_krc::PathSample;
use crate::returns::{BatPath, judge_return};
use crate::udp_tracker::capture_time;
use crate::{SimBall, TrackerModel};
use topspin_core::calib::Calibration;
use topspin_core::physics::{Event, StopAt, Vec3};
use topspin_core::time::{Duration, Instant};

/// A ball's return is found this long after its true crossing of the
/// hitting plane, s (a stroke on time has met it by then).
pub(crate) const JUDGE_AFTER_S: f64 = 0.02;
/// The tracker follows a return this long after the contact, s.
pub(crate) const RETURN_SEEN_S: f64 = 0.2;
/// The bat's path kept before the judging time, s (the stroke's window).
const PATH_BEFORE_S: f64 = 0.2;

/// The returns' datagrams, in the order they arrive.
#[derive(Debug)]
pub(crate) struct ReturnFeed {
    /// The next ball whose return is to be found.
    next_ball: usize,
    queue: VecDeque<Planned>,
    rng: ChaCha8Rng,
    tracker: TrackerModel,
    /// Returns seen (strokes that met their ball).
    pub(crate) seen: usize,
    /// Their frames sent.
    pub(crate) frames: usize,
}

impl ReturnFeed {
    /// A feed for a session of `seed` seen through `tracker`.
    pub(crate) fn new(seed: u64, tracker: TrackerModel) -> Self {
        ReturnFeed {
            next_ball: 0,
            queue: VecDeque::new(),
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x7265_7475_726e_7331),
            tracker,
            seen: 0,
            frames: 0,
        }
    }

    /// When the next ball's return is found (`None`: none left).
    pub(crate) fn due(&self, balls: &[SimBall], starts: &[f64], t0: Instant) -> Option<Instant> {
        let k = self.next_ball;
        let ball = balls.get(k)?;
        Some(capture_time(t0, starts[k], ball.truth.end_t + JUDGE_AFTER_S))
    }

    /// The ball whose return is found next.
    pub(crate) fn next_ball(&self) -> usize {
        self.next_ball
    }

    /// Finds the next ball's return on the bat's `path` so far (at `now`),
    /// near its true crossing `crossing` (s after its launch; the judge's,
    /// `demo::judged`), and queues the frames that see it after `now`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn find(
        &mut self,
        cal: &Calibration,
        balls: &[SimBall],
        starts: &[f64],
        t0: Instant,
        path: &[PathSample],
        crossing: Option<f64>,
        now: Instant,
    ) {
        let k = self.next_ball;
        self.next_ball += 1;
        let ball = &balls[k];
        let Some(crossing) = crossing else { return };
        let from = now.0.saturating_sub(Duration::from_nanos((PATH_BEFORE_S * 1e9) as u64).0);
        let recent = &path[path.partition_point(|s| s.t.0 < from)..];
        let bat = BatPath::new(&cal.robot, recent);
        let launched = capture_time(t0, starts[k], 0.0);
        let judgement = judge_return(cal, &ball.physics, &ball.truth.to_launch(), launched, crossing, &bat);
        let Some((t_touch, mut out)) = judgement.after else { return };
        self.seen += 1;
        let latency = Duration::from_nanos((self.tracker.latency.max(0.0) * 1e9) as u64);
        let period = 1.0 / self.tracker.rate_hz;
        let sigma = self.tracker.noise_sigma.max(0.0);
        let first_seq = return_seq(balls, k);
        let mut t = t_touch;
        let frames = (RETURN_SEEN_S / period).floor() as usize;
        for i in 1..=frames {
            let at = t_touch + i as f64 * period;
            while matches!(ball.physics.advance(&mut out, &mut t, &StopAt::time(at)), Event::Bounce { .. }) {}
            let noise = Vec3::new(
                self.rng.sample::<f64, _>(StandardNormal),
                self.rng.sample::<f64, _>(StandardNormal),
                self.rng.sample::<f64, _>(StandardNormal),
            ) * sigma;
            let lost = self.rng.random::<f64>() < self.tracker.dropout;
            let capture = capture_time(t0, starts[k], at);
            if lost || capture + latency <= now {
                continue;
            }
            let p = out.pos + noise;
            let seq = first_seq.wrapping_add(i as u32 - 1);
            let mut d = observation(seq, capture, [p.x as f32, p.y as f32, p.z as f32]);
            d.at = capture + latency;
            self.queue.push_back(d);
            self.frames += 1;
        }
    }

    /// When the next queued datagram arrives.
    pub(crate) fn next_arrival(&self) -> Option<Instant> {
        self.queue.front().map(|d| d.at)
    }

    /// The next queued datagram.
    pub(crate) fn pop(&mut self) -> Option<Planned> {
        self.queue.pop_front()
    }
}
