//! Fixed-step RK4 propagation of a ball through flight and table bounces,
//! stopping at events. Event times are located inside the step by
//! re-integrating from the step's start (Illinois root finding), so their
//! precision does not depend on the step. Allocates nothing.

use super::{BallState, BounceModel, FlightModel, Table, Vec3};

/// Default integration step in seconds. RK4's error at 4 ms stays below a
/// micrometre over a 0.4 s flight with 400 rad/s of spin
/// (`step_size_does_not_matter`), and events are located inside the step;
/// 4 ms rather than 2 ms halves the estimator's per-observation prediction
/// (its p99 was 63 µs at 2 ms against a 50 µs budget).
pub(crate) const DEFAULT_STEP: f64 = 0.004;

/// Height of the floor below the table surface, m (ITTF: 0.76).
pub(crate) const FLOOR_DEPTH: f64 = 0.76;

/// Where to stop a propagation.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct StopAt {
    /// Absolute time at which to give up, s.
    pub t_max: f64,
    /// Stop where the ball crosses this plane x = const moving towards +x.
    pub hit_plane_x: Option<f64>,
    /// Stop when the ball touches the net.
    pub net: bool,
}

impl StopAt {
    /// Stop at `t_max` only (and at the floor).
    pub fn time(t_max: f64) -> Self {
        StopAt { t_max, hit_plane_x: None, net: false }
    }
}

/// What ended a call to [`Propagator::advance`]. The state it leaves
/// behind is the state at the event (after the bounce for `Bounce`).
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Event {
    /// The ball bounced on the table; `before` is the state at contact
    /// before the impact, the propagated state is after it.
    Bounce {
        /// Time of contact, s.
        t: f64,
        /// State at contact, just before the impact.
        before: BallState,
    },
    /// The ball touched the net.
    Net {
        /// Time of contact with the net, s.
        t: f64,
    },
    /// The ball crossed the hitting plane.
    HitPlane {
        /// Time of the crossing, s.
        t: f64,
    },
    /// The ball reached the floor (also reported when the state stops
    /// being finite).
    Floor {
        /// Time the ball reached the floor, s.
        t: f64,
    },
    /// `t_max` was reached.
    TimeLimit {
        /// Time at which propagation stopped, s.
        t: f64,
    },
}

impl Event {
    /// Absolute time of the event, s.
    pub fn t(&self) -> f64 {
        match *self {
            Event::Bounce { t, .. }
            | Event::Net { t }
            | Event::HitPlane { t }
            | Event::Floor { t }
            | Event::TimeLimit { t } => t,
        }
    }
}

/// Flight model, bounce model and table, integrated with step `dt`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Propagator {
    /// Equation of motion between bounces.
    pub flight: FlightModel,
    /// Table contact model applied at each bounce.
    pub bounce: BounceModel,
    /// Table geometry (bounce area and net).
    pub table: Table,
    /// Fixed RK4 step, s.
    pub dt: f64,
}

#[derive(Copy, Clone, PartialEq, Eq)]
enum Kind {
    Table,
    Net,
    HitPlane,
    Floor,
}

impl Propagator {
    /// A propagator with the default step (4 ms).
    pub fn new(flight: FlightModel, bounce: BounceModel, table: Table) -> Self {
        Propagator { flight, bounce, table, dt: DEFAULT_STEP }
    }

    /// This propagator with the flight's drag and lift multiplied by `scales`.
    pub fn with_scales(&self, scales: super::FlightScales) -> Self {
        Propagator { flight: self.flight.scaled(scales), ..*self }
    }

    /// One RK4 step of length `h` (spin constant in flight).
    #[inline]
    pub(crate) fn rk4(&self, s: &BallState, h: f64) -> BallState {
        let f = &self.flight;
        let (w, rate) = (&s.spin, s.spin.norm());
        let v1 = s.vel;
        let a1 = f.accel_spinning(&v1, w, rate);
        let v2 = s.vel + a1 * (0.5 * h);
        let a2 = f.accel_spinning(&v2, w, rate);
        let v3 = s.vel + a2 * (0.5 * h);
        let a3 = f.accel_spinning(&v3, w, rate);
        let v4 = s.vel + a3 * h;
        let a4 = f.accel_spinning(&v4, w, rate);
        BallState {
            pos: s.pos + (v1 + (v2 + v3) * 2.0 + v4) * (h / 6.0),
            vel: s.vel + (a1 + (a2 + a3) * 2.0 + a4) * (h / 6.0),
            spin: s.spin,
        }
    }

    /// Pure flight (no events) from `s` for `duration` seconds.
    pub fn fly(&self, s: &BallState, duration: f64) -> BallState {
        let mut out = *s;
        let mut left = duration;
        while left > 0.0 {
            let h = left.min(self.dt);
            out = self.rk4(&out, h);
            left -= h;
        }
        out
    }

    fn g(&self, kind: Kind, s: &BallState, stop: &StopAt) -> f64 {
        let r = self.flight.radius();
        match kind {
            Kind::Table => s.pos.z - r,
            Kind::Net => s.pos.x,
            Kind::HitPlane => s.pos.x - stop.hit_plane_x.unwrap_or(f64::INFINITY),
            Kind::Floor => s.pos.z - r + FLOOR_DEPTH,
        }
    }

    /// The fraction of the step `h` from `s0` (to `s1`) at which `g`
    /// changes sign, with the state there.
    fn locate(&self, kind: Kind, s0: &BallState, s1: &BallState, h: f64, stop: &StopAt) -> (f64, BallState) {
        let (mut lo, mut hi) = (0.0, h);
        let mut g_lo = self.g(kind, s0, stop);
        let mut s_hi = *s1;
        let mut g_hi = self.g(kind, &s_hi, stop);
        let mut side = 0i8;
        for _ in 0..40 {
            if hi - lo < 1e-10 {
                break;
            }
            let tau = if g_hi != g_lo { (lo * g_hi - hi * g_lo) / (g_hi - g_lo) } else { 0.5 * (lo + hi) };
            let tau = tau.clamp(lo, hi);
            let s = self.rk4(s0, tau);
            let g = self.g(kind, &s, stop);
            if g == 0.0 {
                return (tau, s);
            }
            if (g > 0.0) == (g_lo > 0.0) {
                lo = tau;
                g_lo = g;
                if side == -1 {
                    g_hi *= 0.5;
                }
                side = -1;
            } else {
                hi = tau;
                g_hi = g;
                s_hi = s;
                if side == 1 {
                    g_lo *= 0.5;
                }
                side = 1;
            }
        }
        (hi, s_hi)
    }

    /// Advances `state` (at time `*t`) until the next event and returns it.
    /// A bounce applies the contact model and returns; call again to go on.
    pub fn advance(&self, state: &mut BallState, t: &mut f64, stop: &StopAt) -> Event {
        let r = self.flight.radius();
        loop {
            if !state.is_finite() {
                return Event::Floor { t: *t };
            }
            let h = self.dt.min(stop.t_max - *t);
            if h <= 0.0 {
                return Event::TimeLimit { t: *t };
            }
            let s0 = *state;
            let s1 = self.rk4(&s0, h);
            // The earliest event inside the step that applies: one that does
            // not (the table crossed past its edge, the net plane beside or
            // above the net) must not hide a later one in the same step.
            let mut event: Option<(f64, Event, BallState)> = None;
            let mut consider = |kind: Kind| {
                let (tau, s) = self.locate(kind, &s0, &s1, h, stop);
                let at = *t + tau;
                let applies = match kind {
                    Kind::Table if self.table.on_surface(s.pos.x, s.pos.y) && s.vel.z < 0.0 => {
                        Some((Event::Bounce { t: at, before: s }, self.bounce.apply(&s)))
                    }
                    Kind::Net if self.table.touches_net(&Vec3::new(0.0, s.pos.y, s.pos.z), r) => {
                        Some((Event::Net { t: at }, s))
                    }
                    Kind::HitPlane => Some((Event::HitPlane { t: at }, s)),
                    Kind::Floor => Some((Event::Floor { t: at }, s)),
                    Kind::Table | Kind::Net => None,
                };
                if let Some((e, after)) = applies
                    && event.is_none_or(|(best, _, _)| tau < best)
                {
                    event = Some((tau, e, after));
                }
            };
            if s0.pos.z - r > 0.0 && s1.pos.z - r <= 0.0 {
                consider(Kind::Table);
            }
            if stop.net && (s0.pos.x < 0.0) != (s1.pos.x < 0.0) {
                consider(Kind::Net);
            }
            if let Some(x) = stop.hit_plane_x
                && s0.pos.x < x
                && s1.pos.x >= x
            {
                consider(Kind::HitPlane);
            }
            if self.g(Kind::Floor, &s1, stop) <= 0.0 {
                consider(Kind::Floor);
            }
            match event {
                Some((tau, event, s)) => {
                    *t += tau;
                    *state = s;
                    return event;
                }
                None => {
                    *state = s1;
                    *t += h;
                    if h < self.dt {
                        return Event::TimeLimit { t: *t };
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::PhysicsParams;
    use proptest::prelude::*;

    fn paper() -> Propagator {
        let p = PhysicsParams::paper();
        Propagator::new(p.flight_model(), p.bounce_model(), Table::default())
    }

    #[test]
    fn rk4_matches_free_fall() {
        let mut p = PhysicsParams::paper();
        p.drag_coefficient = 0.0;
        p.lift = crate::physics::LiftModel::Constant { c_m: 0.0 };
        let prop = Propagator::new(p.flight_model(), p.bounce_model(), Table::default());
        let s = BallState::new(Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 0.0, 2.0), Vec3::zeros());
        let e = prop.fly(&s, 0.3);
        assert!((e.pos.z - (1.0 + 0.6 - 0.5 * 9.81 * 0.09)).abs() < 1e-12);
        assert!((e.pos.x - 0.3).abs() < 1e-12);
    }

    #[test]
    fn step_size_does_not_matter() {
        let s = BallState::new(Vec3::new(-1.5, 0.1, 0.3), Vec3::new(6.0, -0.3, 1.0), Vec3::new(0.0, 400.0, 50.0));
        let mut coarse = paper();
        let mut fine = paper();
        coarse.dt = 0.004;
        fine.dt = 0.0002;
        let a = coarse.fly(&s, 0.4);
        let b = fine.fly(&s, 0.4);
        assert!((a.pos - b.pos).norm() < 1e-6, "{}", (a.pos - b.pos).norm());
    }

    #[test]
    fn an_event_that_does_not_apply_hides_no_later_one_in_its_step() {
        // Past the table's far edge (x 1.37) the ball drops through the
        // table's height at x ≈ 1.42 and crosses the plane x = 1.6 in the
        // same long step: the first is no bounce, the second is the hit.
        let mut prop = paper();
        prop.dt = 0.06;
        let mut s = BallState::new(Vec3::new(1.30, 0.0, 0.03), Vec3::new(6.0, 0.0, -0.5), Vec3::zeros());
        let mut t = 0.0;
        let e = prop.advance(&mut s, &mut t, &StopAt { t_max: 1.0, hit_plane_x: Some(1.6), net: true });
        assert!(matches!(e, Event::HitPlane { .. }), "{e:?}");
        assert!((s.pos.x - 1.6).abs() < 1e-7 && s.pos.z < 0.02, "{s:?}");
    }

    #[test]
    fn serve_bounces_then_crosses_the_hitting_plane() {
        let prop = paper();
        let mut s = BallState::new(Vec3::new(-1.5, 0.0, 0.3), Vec3::new(7.5, 0.0, 1.0), Vec3::new(0.0, 150.0, 0.0));
        let mut t = 0.0;
        let stop = StopAt { t_max: 2.0, hit_plane_x: Some(1.6), net: true };
        let e = prop.advance(&mut s, &mut t, &stop);
        let Event::Bounce { before, .. } = e else { panic!("expected bounce, got {e:?}") };
        assert!((before.pos.z - 0.02).abs() < 1e-7, "contact at z = {}", before.pos.z);
        assert!(before.pos.x > 0.0 && before.pos.x < 1.37, "bounce at {:?}", before.pos);
        assert!(s.vel.z > 0.0);
        let e = prop.advance(&mut s, &mut t, &stop);
        assert!(matches!(e, Event::HitPlane { .. }), "{e:?}");
        assert!((s.pos.x - 1.6).abs() < 1e-7);
    }

    #[test]
    fn low_ball_hits_the_net() {
        let prop = paper();
        let mut s = BallState::new(Vec3::new(-1.0, 0.0, 0.15), Vec3::new(8.0, 0.0, -0.2), Vec3::zeros());
        let mut t = 0.0;
        let e = prop.advance(&mut s, &mut t, &StopAt { t_max: 1.0, hit_plane_x: None, net: true });
        assert!(matches!(e, Event::Net { .. }), "{e:?}");
    }

    proptest! {
        #[test]
        fn without_spin_the_flight_stays_in_its_vertical_plane(
            vx in -10.0..10.0f64, vy in -3.0..3.0f64, vz in -3.0..3.0f64, t in 0.01..0.8f64
        ) {
            prop_assume!(vx.abs() + vy.abs() > 0.1);
            let prop = paper();
            let s0 = BallState::new(Vec3::new(0.0, 0.0, 1.0), Vec3::new(vx, vy, vz), Vec3::zeros());
            let s1 = prop.fly(&s0, t);
            // The horizontal velocity direction is preserved: cross product vanishes.
            let cross = s1.pos.x * vy - s1.pos.y * vx;
            prop_assert!(cross.abs() < 1e-9 * (1.0 + s1.pos.xy().norm() * (vx.abs() + vy.abs())));
            prop_assert!((s1.vel.x * vy - s1.vel.y * vx).abs() < 1e-9 * (1.0 + vx * vx + vy * vy));
        }
    }
}
