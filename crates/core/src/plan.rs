//! The strike plan: what the estimator publishes and the RSI loop executes
//! (DESIGN §6). A plain value, copied through a latest-value slot.

use crate::geometry::EulerZyx;
use crate::physics::Vec3;
use crate::time::{Duration, Instant};

/// The contact criterion the demo judges strokes by (and the view draws):
/// a stroke hits when the bat centre passes within this distance of the
/// ball's centre, m ...
pub const HIT_RADIUS: f64 = 0.040;
/// ... within this much of the ball's true crossing of the hitting plane.
pub const HIT_WINDOW: Duration = Duration::from_millis(4);

/// The bat's face at an orientation.
impl EulerZyx {
    /// The outward normal of the bat's hitting face: −x of the bat (TCP)
    /// frame. The bat hangs below the flange with the blade in the TCP
    /// frame's y–z plane (`calib/robot.toml`), so at the planner's neutral
    /// orientation (0, 0, 0) in T the face is upright and looks at the
    /// opponent (−x_T); b tilts it: b > 0 opens it (the normal rises by b),
    /// b < 0 closes it; a turns it about z; c spins the blade about its own
    /// normal and leaves the face where it is.
    pub fn face_normal(&self) -> Vec3 {
        -self.matrix().column(0).into_owned()
    }
}

/// The face's tilt: the elevation of its outward normal above the
/// horizontal, rad (> 0 open, < 0 closed).
pub fn face_tilt(normal: &Vec3) -> f64 {
    normal.z.clamp(-1.0, 1.0).asin()
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
    /// Bat orientation at the hit ([`EulerZyx::face_normal`] says which
    /// way the face looks).
    pub orientation: EulerZyx,
    /// The ball's spin in flight before its bounce (what the stroke
    /// answers), rad/s.
    pub spin: Vec3,
    /// 0 (guess) … 1 (certain).
    pub confidence: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_neutral_face_looks_at_the_opponent_and_b_opens_it() {
        let n = EulerZyx::default().face_normal();
        assert!((n - Vec3::new(-1.0, 0.0, 0.0)).norm() < 1e-15);
        let open = EulerZyx { a: 0.0, b: 0.3, c: 0.0 }.face_normal();
        assert!((face_tilt(&open) - 0.3).abs() < 1e-12 && open.x < 0.0);
        // a > 0 turns the normal from −x towards −y.
        let turned = EulerZyx { a: 0.2, b: 0.0, c: 0.0 }.face_normal();
        assert!((turned - Vec3::new(-0.2f64.cos(), -0.2f64.sin(), 0.0)).norm() < 1e-12);
        // c spins the blade about its normal: the face stays.
        let spun = EulerZyx { a: 0.0, b: 0.3, c: 0.7 }.face_normal();
        assert!((spun - open).norm() < 1e-12);
    }
}
