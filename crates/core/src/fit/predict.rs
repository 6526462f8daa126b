//! Prediction from a ball state: the next table contact and the crossing of
//! the hitting plane after it (DESIGN §6). Allocation-free, bounded work
//! (the horizon caps the integration).

use crate::physics::{BallState, Event, Propagator, StopAt, Vec3};

/// How far ahead a prediction integrates at most, s.
pub(crate) const PREDICTION_HORIZON: f64 = 2.0;

/// The RK4 step of a prediction, s (or the propagator's, where longer).
/// A flight's accelerations change over tenths of a second, so RK4's error
/// at 10 ms stays in the nanometres over a whole flight (the hitting point
/// against 0.5 ms steps: at most 3 nm over 900 launcher flights,
/// `a_prediction_does_not_depend_on_its_step`), and events are located
/// inside the step. The estimator predicts on every observation: 10 ms
/// against the propagator's 4 ms takes its per-observation p99 back under
/// the 50 µs budget.
pub(crate) const PREDICT_STEP: f64 = 0.010;

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
    /// The next table contact on the robot's half, if the ball bounces
    /// there before the prediction ends.
    pub bounce: Option<Contact>,
    /// The crossing of the hitting plane, if the flight reaches it.
    pub hit: Option<HitPoint>,
    /// How the predicted flight ended.
    pub end: FlightEnd,
}

/// Predicts from `state` at time `t`: the next table contact on the
/// robot's half and the crossing of the plane x = `hit_plane_x` towards +x
/// (after at most one bounce there; a serve's bounce on its own half
/// before it is flown through; a plane over the table counts only after
/// the bounce on the robot's half). `bounced`: the ball has bounced on the
/// robot's half already, so its next bounce there is its second and ends
/// the flight (the ball must be played before it).
pub fn predict(prop: &Propagator, state: &BallState, t: f64, hit_plane_x: f64, bounced: bool) -> Prediction {
    let mut stop = StopAt { t_max: t + PREDICTION_HORIZON, hit_plane_x: Some(hit_plane_x), net: true };
    let prop = &Propagator { dt: prop.dt.max(PREDICT_STEP), ..*prop };
    let (mut s, mut now) = (*state, t);
    let mut bounce = None;
    let end = loop {
        match prop.advance(&mut s, &mut now, &stop) {
            // A serve's bounce on its own half: not a contact the robot plays.
            Event::Bounce { before, .. } if before.pos.x <= 0.0 && bounce.is_none() && !bounced => {}
            Event::Bounce { t, before } => {
                if bounced || bounce.is_some() {
                    break FlightEnd::SecondBounce;
                }
                bounce = Some(Contact { t, pos: before.pos, before, after: s });
                stop.hit_plane_x = Some(hit_plane_x);
            }
            // A plane over the table, reached before the bounce there: the
            // ball is played after it (flown on past the plane).
            Event::HitPlane { .. } if !bounced && bounce.is_none() && s.pos.x < prop.table.robot_end_x() => {
                stop.hit_plane_x = None;
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

/// The crossings of the planes x = `planes[k]` (ascending, m) towards +x
/// from `state` at time `t`, on the flight [`predict`] follows (through at
/// most one bounce on the robot's half, none where `bounced`): `out[k]`
/// for plane k, `None` where the ball is past it already or the flight
/// ends first. One integration for all of them.
///
/// `resume`: the bounce [`predict`] found on this flight (its
/// [`Prediction::bounce`]). Where every plane lies past it, the flight
/// resumes there: up to it the two take the same steps, so the crossings
/// are the same, at half the integration.
pub(crate) fn crossings<const N: usize>(
    prop: &Propagator,
    state: &BallState,
    t: f64,
    planes: &[f64],
    bounced: bool,
    resume: Option<&Contact>,
) -> heapless::Vec<Option<HitPoint>, N> {
    let prop = &Propagator { dt: prop.dt.max(PREDICT_STEP), ..*prop };
    let (mut s, mut now, mut bounced) = match resume {
        Some(c) if !bounced && planes.first().is_some_and(|x| c.pos.x < *x) => (c.after, c.t, true),
        _ => (*state, t, bounced),
    };
    let mut ended = false;
    let mut out = heapless::Vec::new();
    for &x in planes.iter().take(N) {
        let mut crossing = None;
        if !ended && s.pos.x < x {
            let stop = StopAt { t_max: t + PREDICTION_HORIZON, hit_plane_x: Some(x), net: true };
            loop {
                match prop.advance(&mut s, &mut now, &stop) {
                    Event::Bounce { before, .. } if before.pos.x <= 0.0 && !bounced => {}
                    Event::Bounce { .. } if !bounced => bounced = true,
                    Event::HitPlane { t } => {
                        crossing = Some(HitPoint { t, state: s });
                        break;
                    }
                    _ => {
                        ended = true;
                        break;
                    }
                }
            }
        }
        let _ = out.push(crossing);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;

    #[test]
    fn a_prediction_does_not_depend_on_its_step() {
        let cal = Calibration::default_cell();
        let x = cal.strike.hit_plane_x;
        let mut fine = cal.propagator();
        fine.dt = 0.0005;
        let mut n = 0;
        let speeds = [4.5, 5.0, 5.5, 6.0, 6.5, 7.0, 8.0].into_iter();
        for (vx, vz) in speeds.flat_map(|vx| [0.2, 0.6, 1.0, 1.4, 1.8].map(|vz| (vx, vz))) {
            for spin in
                [Vec3::new(0.0, 500.0, 0.0), Vec3::new(0.0, -300.0, 40.0), Vec3::new(60.0, 80.0, 350.0), Vec3::zeros()]
            {
                let s = BallState::new(Vec3::new(-1.5, 0.1, 0.3), Vec3::new(vx, -0.2, vz), spin);
                let p = predict(&cal.propagator(), &s, 0.0, x, false);
                // The reference: the same flight at 0.5 ms steps.
                let (mut r, mut t, mut bounces) = (s, 0.0, 0);
                let stop = StopAt { t_max: PREDICTION_HORIZON, hit_plane_x: Some(x), net: true };
                let reference = loop {
                    match fine.advance(&mut r, &mut t, &stop) {
                        Event::Bounce { before, .. } if before.pos.x <= 0.0 && bounces == 0 => {}
                        Event::Bounce { .. } if bounces == 0 => bounces += 1,
                        Event::HitPlane { t } => break Some((t, r.pos)),
                        _ => break None,
                    }
                };
                assert_eq!(p.hit.is_some(), reference.is_some(), "{s:?}");
                if let (Some(h), Some((t, pos))) = (p.hit, reference) {
                    n += 1;
                    assert!(
                        (h.state.pos - pos).norm() < 1e-7 && (h.t - t).abs() < 1e-8,
                        "{:?} vs {pos:?}",
                        h.state.pos
                    );
                }
            }
        }
        assert!(n >= 40, "{n} flights reach the plane");
    }

    #[test]
    fn a_plane_over_the_table_is_met_after_the_bounce_only() {
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let s = BallState::new(Vec3::new(-1.5, 0.0, 0.3), Vec3::new(5.5, 0.0, 1.4), Vec3::new(0.0, 100.0, 0.0));
        let behind = predict(&prop, &s, 0.0, 1.6, false);
        let bounce = behind.bounce.expect("it bounces on the robot's half");
        assert!((0.3..1.1).contains(&bounce.pos.x), "{bounce:?}");
        // The same bounce (a plane's crossing splits a step of the flight).
        let same =
            |c: Option<Contact>| c.is_some_and(|c| (c.pos - bounce.pos).norm() < 1e-8 && (c.t - bounce.t).abs() < 1e-9);
        // Over the table after the bounce: met there.
        let x = bounce.pos.x + 0.2;
        let after = predict(&prop, &s, 0.0, x, false);
        assert!(same(after.bounce), "{after:?}");
        let hit = after.hit.expect("it crosses the plane after its bounce");
        assert!(hit.t > bounce.t && (hit.state.pos.x - x).abs() < 1e-9);
        // Over the table before the bounce: flown through, and no crossing
        // after it (the ball is past the plane).
        let before = predict(&prop, &s, 0.0, bounce.pos.x - 0.2, false);
        assert!(same(before.bounce), "{before:?}");
        assert!(before.hit.is_none() && before.end == FlightEnd::Floor, "{before:?}");
        // Behind the table, a ball that never bounces is still met.
        let long = BallState { vel: Vec3::new(9.0, 0.0, 2.6), spin: Vec3::zeros(), ..s };
        let p = predict(&prop, &long, 0.0, 1.6, false);
        assert!(p.bounce.is_none() && p.hit.is_some(), "{p:?}");
    }

    #[test]
    fn crossings_are_the_predictions_of_each_plane() {
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let planes = [1.45, 1.50, 1.60, 1.75];
        let s = BallState::new(Vec3::new(-1.5, 0.1, 0.3), Vec3::new(5.5, -0.2, 1.4), Vec3::new(0.0, 100.0, 0.0));
        let first = predict(&prop, &s, 0.2, planes[0], false);
        assert_eq!(first.end, FlightEnd::HitPlane, "{first:?}");
        let c = crossings::<4>(&prop, &s, 0.2, &planes, false, None);
        assert_eq!(c.len(), 4);
        for (x, got) in planes.iter().zip(&c) {
            let one = predict(&prop, &s, 0.2, *x, false).hit.expect("it reaches every plane");
            let got = got.expect("a crossing");
            assert!((got.state.pos - one.state.pos).norm() < 1e-6 && (got.t - one.t).abs() < 1e-7, "{x}");
            assert!((got.state.pos.x - x).abs() < 1e-9);
        }
        // Past the first plane already: none there, the others as before.
        let later = BallState { pos: Vec3::new(1.47, c[0].unwrap().state.pos.y, 0.3), ..c[0].unwrap().state };
        let c2 = crossings::<4>(&prop, &later, 0.0, &planes, false, None);
        assert!(c2[0].is_none() && c2[1].is_some());
    }

    #[test]
    fn crossings_resumed_at_the_predicted_bounce_are_the_same() {
        use rand::{Rng, SeedableRng};
        use rand_chacha::ChaCha8Rng;
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let planes = [1.45, 1.50, 1.55, 1.60];
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut next = || rng.random::<f64>();
        let mut resumed = 0;
        for _ in 0..200 {
            let s = BallState::new(
                Vec3::new(-1.6 + 0.8 * next(), 0.3 * (next() - 0.5), 0.2 + 0.2 * next()),
                Vec3::new(4.0 + 3.0 * next(), 0.6 * (next() - 0.5), 0.5 + 1.5 * next()),
                Vec3::new(0.0, 600.0 * (next() - 0.5), 100.0 * (next() - 0.5)),
            );
            let p = predict(&prop, &s, 0.1, 1.60, false);
            let whole = crossings::<4>(&prop, &s, 0.1, &planes, false, None);
            let short = crossings::<4>(&prop, &s, 0.1, &planes, false, p.bounce.as_ref());
            assert_eq!(whole, short, "{s:?}");
            resumed += usize::from(p.bounce.is_some() && whole.iter().any(Option::is_some));
        }
        assert!(resumed > 100, "{resumed} flights resumed at a bounce and crossed a plane");
        // A plane before the bounce: the whole flight.
        let s = BallState::new(Vec3::new(-1.5, 0.0, 0.3), Vec3::new(5.5, 0.0, 1.4), Vec3::new(0.0, 100.0, 0.0));
        let p = predict(&prop, &s, 0.0, 1.60, false);
        let early = [-0.5, 1.60];
        let c = crossings::<2>(&prop, &s, 0.0, &early, false, p.bounce.as_ref());
        assert!(c[0].is_some() && c == crossings::<2>(&prop, &s, 0.0, &early, false, None));
    }

    #[test]
    fn a_ball_that_has_bounced_is_played_before_it_bounces_again() {
        // A slow ball just off its bounce at x = 0.5 m: it comes down on
        // the table again short of the hitting plane.
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let x = cal.strike.hit_plane_x;
        let s = BallState::new(Vec3::new(0.5, 0.4, 0.05), Vec3::new(1.7, -0.1, 2.3), Vec3::zeros());
        let flown_on = predict(&prop, &s, 0.0, x, false);
        let second = flown_on.bounce.expect("it comes down again");
        assert!(second.pos.x < 1.37, "{second:?}");
        assert_eq!(flown_on.end, FlightEnd::HitPlane, "unaware of the first bounce, it plays past the second");
        let played = predict(&prop, &s, 0.0, x, true);
        assert_eq!((played.bounce, played.hit, played.end), (None, None, FlightEnd::SecondBounce));
        let planes = [0.9, x];
        let c = crossings::<2>(&prop, &s, 0.0, &planes, true, None);
        assert!(c[0].is_some() && c[1].is_none(), "{c:?}");
        assert!(crossings::<2>(&prop, &s, 0.0, &planes, false, None)[1].is_some());
    }
}
