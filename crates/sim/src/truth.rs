//! Ground truth of a launched ball, computed with the same propagator that
//! generates the observations: launch state, spin, bounce, net crossing and
//! the crossing of the hitting plane. Serialized into `ball-NNN.json`; the
//! field names are a contract with the evaluation code.

use serde::{Deserialize, Serialize};

use super::launcher::{Launch, Setting};
use topspin_core::calib::StrikeCalib;
use topspin_core::physics::{BallState, Event, Propagator, StopAt, Vec3};

/// Longest flight followed, s.
pub(crate) const FLIGHT_T_MAX: f64 = 3.0;

/// A ball state in plain arrays (SI, table frame).
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StateRecord {
    /// Position, m.
    pub pos: [f64; 3],
    /// Velocity, m/s.
    pub vel: [f64; 3],
    /// Spin, rad/s.
    pub spin: [f64; 3],
}

impl From<&BallState> for StateRecord {
    fn from(s: &BallState) -> Self {
        StateRecord { pos: s.pos.into(), vel: s.vel.into(), spin: s.spin.into() }
    }
}

impl From<&StateRecord> for BallState {
    fn from(s: &StateRecord) -> Self {
        BallState::new(s.pos.into(), s.vel.into(), s.spin.into())
    }
}

/// The table contact on the robot's half.
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BounceTruth {
    /// Time of contact, s after launch.
    pub t: f64,
    /// Ball centre at contact, m.
    pub pos: [f64; 3],
    /// Velocity just before the contact, m/s.
    pub vel_before: [f64; 3],
    /// Velocity just after the contact, m/s.
    pub vel_after: [f64; 3],
    /// Spin after the contact, rad/s.
    pub spin_after: [f64; 3],
}

/// The crossing of the hitting plane after the bounce.
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HitTruth {
    /// Time, s after launch.
    pub t: f64,
    /// Ball centre, m (x = hit_plane_x).
    pub pos: [f64; 3],
    /// Velocity, m/s.
    pub vel: [f64; 3],
    /// Spin, rad/s.
    pub spin: [f64; 3],
}

/// Everything true about one simulated flight.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Launcher setting, e.g. `"topspin-high"`.
    pub setting: Setting,
    /// State at launch (t = 0).
    pub launch: StateRecord,
    /// Spin in flight before the bounce, rad/s (constant).
    pub spin: [f64; 3],
    /// ‖spin‖ in revolutions per second, for people.
    pub spin_rps: f64,
    /// The first table contact on the robot's half, or null.
    pub bounce: Option<BounceTruth>,
    /// When the ball crossed the net plane x = 0, s, or null.
    pub net_crossing_t: Option<f64>,
    /// The hitting plane, m.
    pub hit_plane_x: f64,
    /// The crossing of the hitting plane after the bounce (and before a
    /// second bounce on the robot's half), or null.
    pub hit: Option<HitTruth>,
    /// When the flight ends for the tracker: the hit, else the floor or
    /// the time limit, s.
    pub end_t: f64,
}

impl Truth {
    /// Follows `launch` with `prop` to the hitting plane (or the floor).
    pub fn compute(launch: &Launch, prop: &Propagator, hit_plane_x: f64) -> Truth {
        let s0 = launch.state;
        // Net crossing: stop at the plane x = 0 without a net.
        let net_crossing_t = (s0.pos.x < 0.0)
            .then(|| {
                let (mut s, mut t) = (s0, 0.0);
                loop {
                    match prop.advance(
                        &mut s,
                        &mut t,
                        &StopAt { t_max: FLIGHT_T_MAX, hit_plane_x: Some(0.0), net: false },
                    ) {
                        Event::HitPlane { t } => break Some(t),
                        Event::Bounce { .. } => continue,
                        _ => break None,
                    }
                }
            })
            .flatten();

        let stop = StopAt { t_max: FLIGHT_T_MAX, hit_plane_x: Some(hit_plane_x), net: false };
        let (mut s, mut t) = (s0, 0.0);
        let mut bounce = None;
        let mut bounced_twice = false;
        let mut hit = None;
        let end_t = loop {
            match prop.advance(&mut s, &mut t, &stop) {
                Event::Bounce { t, before } => {
                    // A serve's bounce on its own half is not the one played.
                    bounced_twice |= bounce.is_some() && before.pos.x > 0.0;
                    if bounce.is_none() && before.pos.x > 0.0 {
                        bounce = Some(BounceTruth {
                            t,
                            pos: before.pos.into(),
                            vel_before: before.vel.into(),
                            vel_after: s.vel.into(),
                            spin_after: s.spin.into(),
                        });
                    }
                }
                Event::HitPlane { t } => {
                    if bounce.is_some() && !bounced_twice {
                        hit = Some(HitTruth { t, pos: s.pos.into(), vel: s.vel.into(), spin: s.spin.into() });
                    }
                    break t;
                }
                e => break e.t(),
            }
        };
        Truth {
            setting: launch.setting,
            launch: (&s0).into(),
            spin: s0.spin.into(),
            spin_rps: topspin_core::physics::rad_to_rps(s0.spin.norm()),
            bounce,
            net_crossing_t,
            hit_plane_x,
            hit,
            end_t,
        }
    }

    /// The crossing of the plane x after the bounce on the robot's half
    /// and before a second one there, flown with `prop` (the ball's own
    /// physics): [`Truth::hit`] for another plane of the hitting volume.
    pub fn crossing_at(&self, prop: &Propagator, x: f64) -> Option<HitTruth> {
        if x == self.hit_plane_x {
            return self.hit;
        }
        let stop = StopAt { t_max: FLIGHT_T_MAX, hit_plane_x: Some(x), net: false };
        let (mut s, mut t) = (BallState::from(&self.launch), 0.0);
        let mut bounced = false;
        loop {
            match prop.advance(&mut s, &mut t, &stop) {
                // A second bounce on the robot's half: the ball was not
                // played in time.
                Event::Bounce { before, .. } if bounced && before.pos.x > 0.0 => return None,
                Event::Bounce { before, .. } => bounced |= before.pos.x > 0.0,
                Event::HitPlane { t } if bounced => {
                    return Some(HitTruth { t, pos: s.pos.into(), vel: s.vel.into(), spin: s.spin.into() });
                }
                _ => return None,
            }
        }
    }

    /// Where the ball can be met in the hitting volume of `strike`: its
    /// crossing of the hitting plane where that lies in the window, else of
    /// the nearest other plane of the volume where that does (flying, in
    /// the physics `prop`, only as far as the first plane that works).
    /// `None`: out of reach.
    pub fn meeting_in(&self, strike: &StrikeCalib, prop: &Propagator) -> Option<HitTruth> {
        let planes = strike.hitting_planes();
        strike.planes_outwards().find_map(|k| {
            let x = planes[k];
            self.crossing_at(prop, x).filter(|h| strike.in_window_at(x, h.pos[1], h.pos[2]))
        })
    }

    /// The launch as a [`Launch`] again.
    pub fn to_launch(&self) -> Launch {
        Launch { setting: self.setting, state: (&self.launch).into() }
    }
}

/// Walks one flight forward in time, through bounces (no net, no plane).
#[derive(Copy, Clone, Debug)]
pub struct Flight<'a> {
    prop: &'a Propagator,
    state: BallState,
    t: f64,
}

impl<'a> Flight<'a> {
    /// Starts at the launch (t = 0).
    pub fn new(launch: &Launch, prop: &'a Propagator) -> Self {
        Flight { prop, state: launch.state, t: 0.0 }
    }

    /// The state at `t` (≥ the last time asked; earlier times return the
    /// current state). After the floor the ball stays where it landed.
    pub fn at(&mut self, t: f64) -> BallState {
        let stop = StopAt::time(t);
        while self.t < t {
            match self.prop.advance(&mut self.state, &mut self.t, &stop) {
                Event::Bounce { .. } => continue,
                Event::Floor { .. } => break,
                _ => {
                    // TimeLimit: land exactly on `t`.
                    self.t = self.t.max(t);
                    break;
                }
            }
        }
        self.state
    }
}

/// The true state of `launch` at `t` s after launch, through the bounce.
pub fn true_state_at(launch: &Launch, prop: &Propagator, t: f64) -> BallState {
    Flight::new(launch, prop).at(t)
}

/// Position only, for callers that want a plain vector.
pub fn true_position_at(launch: &Launch, prop: &Propagator, t: f64) -> Vec3 {
    true_state_at(launch, prop, t).pos
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::launcher::launch;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use topspin_core::calib::Calibration;

    #[test]
    fn truth_is_consistent_with_the_flight() {
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let x_hit = cal.strike.hit_plane_x;
        for (k, setting) in Setting::ALL.into_iter().enumerate() {
            let mut rng = ChaCha8Rng::seed_from_u64(k as u64);
            let l = launch(setting, &prop, x_hit, &mut rng).unwrap();
            let truth = Truth::compute(&l, &prop, x_hit);
            let b = truth.bounce.unwrap();
            let h = truth.hit.unwrap();
            let n = truth.net_crossing_t.unwrap();
            assert!(0.0 < n && n < b.t && b.t < h.t && h.t == truth.end_t);
            assert!(b.pos[0] > 0.0 && (b.pos[2] - 0.02).abs() < 1e-6);
            assert!((h.pos[0] - x_hit).abs() < 1e-6);
            let at_hit = true_state_at(&l, &prop, h.t);
            assert!((at_hit.pos - Vec3::from(h.pos)).norm() < 1e-6);
            let at_net = true_position_at(&l, &prop, n);
            assert!(at_net.x.abs() < 1e-6 && at_net.z > cal.table.net_height + 0.02);
            let json = serde_json::to_string(&truth).unwrap();
            let back: Truth = serde_json::from_str(&json).unwrap();
            // serde_json parses floats to within an ulp, not bit for bit.
            assert_eq!(back.setting, truth.setting);
            let hb = back.hit.unwrap();
            assert!((hb.t - h.t).abs() < 1e-12 && (hb.pos[1] - h.pos[1]).abs() < 1e-12);
            assert!((back.spin[1] - truth.spin[1]).abs() < 1e-9);
        }
    }
}
