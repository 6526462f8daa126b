//! The stroke (DESIGN §6, paper §VI): from the predicted ball at the
//! hitting plane and its spin to the bat's orientation and velocity, and
//! the check that the plan stays in the hitting window.
//!
//! Two ways to set the face (`strike.aim`): `landing` (the default) aims
//! the return at a point on the opponent's half through the racket contact
//! model ([`super::aim`]); `paper` is the paper's rule — β linear in ω_y
//! between the topspin and backspin angles (clamped), A and C from the
//! hitting point's y, the bat at `bat_speed` towards the opponent.
//!
//! The paper's angles are in the robot's frame: x towards the opponent,
//! y to its left, z up — T turned half a turn about z — where β > 0 closes
//! the face (tilts its normal, +x there, down), as a topspin ball needs. In
//! T (x towards the robot) the same bat is Rz(π)·R·Rz(π)ᵀ: a = A(−y),
//! b = −β, c = −C(−y). (Used as they stood in T, the angles opened the face
//! to topspin and closed it to backspin, and turned it away from the
//! table: 1 return in 16, `topspin demo`.)

use crate::calib::StrikeCalib;
use crate::fit::HitPoint;
use crate::geometry::EulerZyx;
use crate::physics::Vec3;

/// Why no plan was published for a prediction.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Withheld {
    /// The predicted flight never reaches the hitting plane.
    NoHit,
    /// The hitting point is outside the hitting window (y).
    OutsideY,
    /// The hitting point is outside the hitting window (z).
    OutsideZ,
    /// The hit would come too soon for the robot.
    TooSoon,
    /// Inside the window, but the arm cannot present a face there at the
    /// aim's slowest bat (the reach map: the window's wide high corners).
    OutOfReach,
}

/// The paper's β for spin ω_y, rad (positive closes the face): +β_top at
/// ω_y = +ω_ref, β_back at −ω_ref, linear between, clamped.
pub fn paper_beta(cal: &StrikeCalib, spin: &Vec3) -> f64 {
    let u = (spin.y / cal.spin_ref).clamp(-1.0, 1.0);
    let (top, back) = (cal.beta_topspin_deg.to_radians(), cal.beta_backspin_deg.to_radians());
    0.5 * (top + back) + 0.5 * (top - back) * u
}

/// The bat's orientation in T by the paper's rule for a ball with spin
/// `spin` crossing at `y` (see the module doc for the frame).
pub(crate) fn bat_orientation(cal: &StrikeCalib, spin: &Vec3, y: f64) -> EulerZyx {
    let y_robot = -y;
    EulerZyx {
        a: (cal.a0_deg + cal.a_per_y_deg * y_robot).to_radians(),
        b: -paper_beta(cal, spin),
        c: -(cal.c0_deg + cal.c_per_y_deg * y_robot).to_radians(),
    }
}

/// The roll about the face's normal (Euler c in T) for a hit at `y`: the
/// paper's C, which does not move the face.
pub(crate) fn bat_roll(cal: &StrikeCalib, y: f64) -> f64 {
    -(cal.c0_deg - cal.c_per_y_deg * y).to_radians()
}

/// The bat velocity at the hit by the paper's rule: `bat_speed` towards
/// the opponent (−x).
pub(crate) fn bat_velocity(cal: &StrikeCalib) -> Vec3 {
    Vec3::new(-cal.bat_speed, 0.0, 0.0)
}

/// Checks the hitting point against the window; `lead` is the time left
/// until the hit, s.
pub(crate) fn check(cal: &StrikeCalib, hit: &HitPoint, lead: f64) -> Result<(), Withheld> {
    let p = hit.state.pos;
    if !(cal.window_y[0]..=cal.window_y[1]).contains(&p.y) {
        return Err(Withheld::OutsideY);
    }
    if !(cal.window_z[0]..=cal.window_z[1]).contains(&p.z) {
        return Err(Withheld::OutsideZ);
    }
    if lead < cal.min_lead_time {
        return Err(Withheld::TooSoon);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;

    #[test]
    fn beta_follows_the_papers_rule() {
        let cal = Calibration::default_cell().strike;
        let at = |wy: f64| paper_beta(&cal, &Vec3::new(0.0, wy, 0.0)).to_degrees();
        assert!((at(cal.spin_ref) - 28.0).abs() < 1e-9);
        assert!((at(-cal.spin_ref) + 40.0).abs() < 1e-9);
        assert!((at(0.0) + 6.0).abs() < 1e-9);
        assert!((at(10.0 * cal.spin_ref) - 28.0).abs() < 1e-9);
        assert!((at(-10.0 * cal.spin_ref) + 40.0).abs() < 1e-9);
    }

    #[test]
    fn the_papers_angles_close_the_face_to_topspin_and_turn_it_to_the_middle() {
        let cal = Calibration::default_cell().strike;
        let top = bat_orientation(&cal, &Vec3::new(0.0, cal.spin_ref, 0.0), 0.0).face_normal();
        let back = bat_orientation(&cal, &Vec3::new(0.0, -cal.spin_ref, 0.0), 0.0).face_normal();
        assert!((crate::plan::face_tilt(&top).to_degrees() + 28.0).abs() < 1e-9, "{top}");
        assert!((crate::plan::face_tilt(&back).to_degrees() - 40.0).abs() < 1e-9, "{back}");
        // A ball on the robot's left of the table (y > 0 in T) is sent back
        // towards the middle: the face looks towards −y.
        let o = bat_orientation(&cal, &Vec3::zeros(), 0.5);
        assert!(o.face_normal().y < -0.1 && o.face_normal().x < 0.0, "{}", o.face_normal());
        assert!((o.c - bat_roll(&cal, 0.5)).abs() < 1e-12);
    }
}
