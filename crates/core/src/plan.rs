//! The strike plan: what the estimator publishes and the RSI loop executes
//! (DESIGN §6). A plain value, copied through a latest-value slot.

use crate::physics::Vec3;
use crate::time::{Duration, Instant};

/// The contact criterion the demo judges strokes by (and the view draws):
/// a stroke hits when the bat centre passes within this distance of the
/// ball's centre, m ...
pub const HIT_RADIUS: f64 = 0.040;
/// ... within this much of the ball's true crossing of the hitting plane.
pub const HIT_WINDOW: Duration = Duration::from_millis(4);

/// A bat orientation as KUKA Euler angles ZYX in radians: rotate by `a`
/// about z, then `b` about the new y, then `c` about the new x.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct EulerZyx {
    /// First rotation, about z, rad.
    pub a: f64,
    /// Second rotation, about the new y, rad.
    pub b: f64,
    /// Third rotation, about the new x, rad.
    pub c: f64,
}

/// Where, when and how the bat should meet the ball. All vectors in the
/// table frame T, SI units.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct StrikePlan {
    /// Increases with every published plan.
    pub seq: u32,
    /// The ball (trajectory) this plan answers.
    pub trajectory: u32,
    /// When the plan was made.
    pub made_at: Instant,
    /// When the bat should meet the ball.
    pub hit_time: Instant,
    /// Bat centre (the TCP) at the hit: the predicted ball centre.
    pub position: Vec3,
    /// Bat velocity at the hit.
    pub velocity: Vec3,
    /// Bat orientation at the hit.
    pub orientation: EulerZyx,
    /// The ball's spin in flight before its bounce (what the stroke
    /// answers), rad/s.
    pub spin: Vec3,
    /// 0 (guess) … 1 (certain).
    pub confidence: f64,
}
