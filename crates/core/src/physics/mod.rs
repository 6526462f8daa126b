//! Ball physics in the table frame T (DESIGN §2, §3): the flight model
//! (drag, Magnus lift, gravity), the table and net, the table bounce, the
//! bat's rubber (the racket contact), a fixed-step RK4 propagator that
//! stops at events (bounce, net, hitting plane), and a flight's
//! sensitivities to its start and its drag and lift. Pure functions of their
//! inputs: no clock, no I/O, no allocation.

pub(crate) mod bounce;
pub(crate) mod flight;
pub(crate) mod params;
pub(crate) mod propagate;
pub(crate) mod racket;
pub(crate) mod sensitivity;
pub(crate) mod table;

pub use bounce::BounceModel;
pub use flight::{FlightModel, FlightScales, LiftModel, LiftPoints};
pub use params::{FlightVariation, InvalidParam, PhysicsParams};
pub use propagate::{Event, Propagator, StopAt};
pub use racket::{Bat, Impact, RacketModel, RacketParams, Regime};
pub use sensitivity::Sensitivities;
pub use table::Table;

/// A 3-vector in SI units in the table frame.
pub type Vec3 = nalgebra::Vector3<f64>;

/// Everything that determines a ball's future: position (m), velocity
/// (m/s) and spin (rad/s), all in the table frame.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BallState {
    /// Ball centre in the table frame T, m.
    pub pos: Vec3,
    /// Ball velocity in T, m/s.
    pub vel: Vec3,
    /// Ball angular velocity (spin) in T, rad/s.
    pub spin: Vec3,
}

impl BallState {
    /// A state from position (m), velocity (m/s) and spin (rad/s) in T.
    pub fn new(pos: Vec3, vel: Vec3, spin: Vec3) -> Self {
        BallState { pos, vel, spin }
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.pos.iter().chain(self.vel.iter()).chain(self.spin.iter()).all(|c| c.is_finite())
    }
}

/// Revolutions per second from rad/s.
pub fn rad_to_rps(w: f64) -> f64 {
    w / std::f64::consts::TAU
}

/// rad/s from revolutions per second.
pub fn rps_to_rad(rps: f64) -> f64 {
    rps * std::f64::consts::TAU
}
