//! The stroke (DESIGN §6, paper §VI): from the predicted ball at the
//! hitting plane and its spin to a strike plan — bat orientation as KUKA
//! Euler ZYX with β linear in ω_y between the topspin and backspin angles
//! (clamped), A and C from the hitting point's y, bat velocity towards the
//! opponent — and the check that the plan stays in the hitting window.

use crate::calib::StrikeCalib;
use crate::fit::HitPoint;
use crate::physics::Vec3;
use crate::plan::EulerZyx;

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
}

/// The bat's orientation for a ball with spin `spin` crossing at `y`.
pub(crate) fn bat_orientation(cal: &StrikeCalib, spin: &Vec3, y: f64) -> EulerZyx {
    // β = +β_top at ω_y = +ω_ref, β_back at −ω_ref, linear between, clamped.
    let u = (spin.y / cal.spin_ref).clamp(-1.0, 1.0);
    let (top, back) = (cal.beta_topspin_deg.to_radians(), cal.beta_backspin_deg.to_radians());
    let b = 0.5 * (top + back) + 0.5 * (top - back) * u;
    EulerZyx {
        a: (cal.a0_deg + cal.a_per_y_deg * y).to_radians(),
        b,
        c: (cal.c0_deg + cal.c_per_y_deg * y).to_radians(),
    }
}

/// The bat velocity at the hit: `bat_speed` towards the opponent (−x).
pub(crate) fn bat_velocity(cal: &StrikeCalib) -> Vec3 {
    Vec3::new(-cal.bat_speed, 0.0, 0.0)
}

/// Checks the hitting point against the window; `lead` is the time left
/// until the hit, s.
pub fn check(cal: &StrikeCalib, hit: &HitPoint, lead: f64) -> Result<(), Withheld> {
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
        let at = |wy: f64| bat_orientation(&cal, &Vec3::new(0.0, wy, 0.0), 0.0).b.to_degrees();
        assert!((at(cal.spin_ref) - 28.0).abs() < 1e-9);
        assert!((at(-cal.spin_ref) + 40.0).abs() < 1e-9);
        assert!((at(0.0) + 6.0).abs() < 1e-9);
        assert!((at(10.0 * cal.spin_ref) - 28.0).abs() < 1e-9);
        assert!((at(-10.0 * cal.spin_ref) + 40.0).abs() < 1e-9);
    }
}
