//! Prediction from a ball state: the next table contact and the crossing of
//! the hitting plane after it (DESIGN §6). Allocation-free, bounded work
//! (the horizon caps the integration).

use crate::physics::{BallState, Event, Propagator, StopAt, Vec3};

/// How far ahead a prediction integrates at most, s.
pub(crate) const PREDICTION_HORIZON: f64 = 2.0;

/// A predicted table contact.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Contact {
    /// Time of contact, s (the caller's clock).
    pub t: f64,
    /// Ball centre at contact, m (table frame T).
    pub pos: Vec3,
    /// State at contact just before the impact.
    pub before: BallState,
    /// State at contact just after the impact.
    pub after: BallState,
}

/// The predicted crossing of the hitting plane.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct HitPoint {
    /// Time of the crossing, s (the caller's clock).
    pub t: f64,
    /// Ball state at the crossing.
    pub state: BallState,
}

/// Where the predicted flight ends if it never reaches the hitting plane.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum FlightEnd {
    /// Crossed the hitting plane.
    HitPlane,
    /// Caught by the net.
    Net,
    /// Reached the floor (missed the table, or bounced twice short).
    Floor,
    /// Bounced twice before the hitting plane.
    SecondBounce,
    /// Still flying at the horizon.
    Horizon,
}

/// Next contact (if the ball is still to bounce) and the hitting point.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Prediction {
    /// The next table contact, if the ball bounces before the prediction ends.
    pub bounce: Option<Contact>,
    /// The crossing of the hitting plane, if the flight reaches it.
    pub hit: Option<HitPoint>,
    /// How the predicted flight ended.
    pub end: FlightEnd,
}

/// Predicts from `state` at time `t`: the next table contact and the
/// crossing of the plane x = `hit_plane_x` towards +x (after at most one
/// bounce).
pub fn predict(prop: &Propagator, state: &BallState, t: f64, hit_plane_x: f64) -> Prediction {
    let stop = StopAt { t_max: t + PREDICTION_HORIZON, hit_plane_x: Some(hit_plane_x), net: true };
    let (mut s, mut now) = (*state, t);
    let mut bounce = None;
    let end = loop {
        match prop.advance(&mut s, &mut now, &stop) {
            Event::Bounce { t, before } => {
                if bounce.is_some() {
                    break FlightEnd::SecondBounce;
                }
                bounce = Some(Contact { t, pos: before.pos, before, after: s });
            }
            Event::HitPlane { t } => {
                return Prediction { bounce, hit: Some(HitPoint { t, state: s }), end: FlightEnd::HitPlane };
            }
            Event::Net { .. } => break FlightEnd::Net,
            Event::Floor { .. } => break FlightEnd::Floor,
            Event::TimeLimit { .. } => break FlightEnd::Horizon,
        }
    };
    Prediction { bounce, hit: None, end }
}
