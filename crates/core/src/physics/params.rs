//! The physical constants of ball, air and table contact, as they appear in
//! `calib/physics.toml`. The paper's values are one preset; the calibrated
//! defaults are another. Everything derived from them (k_D, k_M, the bounce
//! matrices) is computed once, when a model is built.

use serde::{Deserialize, Serialize};

use super::{BounceModel, FlightModel, LiftModel};

/// Ball, air and contact constants (SI units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicsParams {
    /// Ball mass in kg.
    pub mass: f64,
    /// Ball radius in m.
    pub radius: f64,
    /// Gravitational acceleration in m/s².
    pub gravity: f64,
    /// Air density in kg/m³.
    pub air_density: f64,
    /// Drag coefficient C_D.
    pub drag_coefficient: f64,
    /// Magnus lift model (C_M, possibly falling with the spin parameter).
    pub lift: LiftModel,
    /// Coefficient of restitution of the table bounce (normal direction).
    pub restitution: f64,
    /// Coulomb friction coefficient ball–table.
    pub friction: f64,
    /// How far one flight's drag and lift may stray from the calibration
    /// (the refined fit's prior on the per-flight scales).
    #[serde(default, rename = "flight_variation")]
    pub variation: FlightVariation,
}

/// Prior spread of the per-flight drag and lift multipliers
/// ([`super::FlightScales`]), as the widths of priors on their natural
/// logarithms (Gaussian for the drag, Cauchy for the lift): 0.15 lets a
/// flight's drag stray about ±15 % at 1σ.
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlightVariation {
    /// σ of ln(drag multiplier).
    pub drag: f64,
    /// σ of ln(lift multiplier).
    pub lift: f64,
}

impl Default for FlightVariation {
    /// C_D of 40 mm balls is measured between 0.40 and 0.55 (DESIGN §3):
    /// ±12 % about the calibration, so σ 0.15. The lift is given the same
    /// width, but as the scale of a heavy-tailed (Cauchy) prior: the lift
    /// codes in use disagree by a factor of 4.6 (0.32·S to 1.47·S), so a
    /// flight must be able to move it far when its data insist.
    fn default() -> Self {
        FlightVariation { drag: 0.15, lift: 0.1 }
    }
}

impl PhysicsParams {
    /// The paper's constants (Tebbe et al. 2020, §IV): m = 2.7 g, r = 20 mm,
    /// C_D = 0.4, C_M = 0.6, ρ = 1.29 kg/m³, g = 9.81 m/s²; bounce e = 0.90,
    /// μ = 0.25.
    pub fn paper() -> Self {
        PhysicsParams {
            mass: 0.0027,
            radius: 0.02,
            gravity: 9.81,
            air_density: 1.29,
            drag_coefficient: 0.4,
            lift: LiftModel::Constant { c_m: 0.6 },
            restitution: 0.90,
            friction: 0.25,
            variation: FlightVariation::default(),
        }
    }

    /// Checks that every value is finite and physically meaningful; names
    /// the first offending key.
    pub fn validate(&self) -> Result<(), InvalidParam> {
        let positive = [
            ("mass", self.mass),
            ("radius", self.radius),
            ("gravity", self.gravity),
            ("air_density", self.air_density),
        ];
        for (key, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(InvalidParam { key, value: v });
            }
        }
        if !(self.drag_coefficient.is_finite() && self.drag_coefficient >= 0.0) {
            return Err(InvalidParam { key: "drag_coefficient", value: self.drag_coefficient });
        }
        match self.lift {
            LiftModel::Constant { c_m } if !(c_m.is_finite() && c_m >= 0.0) => {
                return Err(InvalidParam { key: "lift.c_m", value: c_m });
            }
            LiftModel::Saturating { c_m, .. } if !(c_m.is_finite() && c_m >= 0.0) => {
                return Err(InvalidParam { key: "lift.c_m", value: c_m });
            }
            LiftModel::Saturating { s_half, .. } if !(s_half.is_finite() && s_half > 0.0) => {
                return Err(InvalidParam { key: "lift.s_half", value: s_half });
            }
            LiftModel::Crisis { c_m, s_half, s_valley, depth, width } => {
                let checks = [
                    ("lift.c_m", c_m, c_m >= 0.0),
                    ("lift.s_half", s_half, s_half > 0.0),
                    ("lift.s_valley", s_valley, s_valley >= 0.0),
                    ("lift.depth", depth, (0.0..=1.0).contains(&depth)),
                    ("lift.width", width, width > 0.0),
                ];
                if let Some((key, value, _)) = checks.into_iter().find(|(_, v, ok)| !(v.is_finite() && *ok)) {
                    return Err(InvalidParam { key, value });
                }
            }
            LiftModel::Measured { s, c_l } => {
                let (s, c_l) = (s.as_slice(), c_l.as_slice());
                if s.len() != c_l.len() {
                    return Err(InvalidParam { key: "lift.c_l", value: c_l.len() as f64 });
                }
                let mut last = 0.0;
                for &v in s {
                    if !(v.is_finite() && v > last) {
                        return Err(InvalidParam { key: "lift.s", value: v });
                    }
                    last = v;
                }
                if let Some(&v) = c_l.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
                    return Err(InvalidParam { key: "lift.c_l", value: v });
                }
            }
            _ => {}
        }
        for (key, v) in [("flight_variation.drag", self.variation.drag), ("flight_variation.lift", self.variation.lift)]
        {
            if !(v.is_finite() && v >= 0.0) {
                return Err(InvalidParam { key, value: v });
            }
        }
        if !(self.restitution.is_finite() && (0.0..=1.0).contains(&self.restitution)) {
            return Err(InvalidParam { key: "restitution", value: self.restitution });
        }
        if !(self.friction.is_finite() && self.friction >= 0.0) {
            return Err(InvalidParam { key: "friction", value: self.friction });
        }
        Ok(())
    }

    /// The flight model these constants define.
    pub fn flight_model(&self) -> FlightModel {
        FlightModel::new(self)
    }

    /// The table-bounce model these constants define.
    pub fn bounce_model(&self) -> BounceModel {
        BounceModel::new(self.restitution, self.friction, self.radius)
    }
}

/// A physics constant outside its meaningful range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("physics parameter `{key}` = {value} is out of range")]
pub struct InvalidParam {
    /// The offending key as named in `calib/physics.toml` (e.g. `lift.c_m`).
    pub key: &'static str,
    /// The value it had.
    pub value: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_constants_give_the_papers_coefficients() {
        let m = PhysicsParams::paper().flight_model();
        assert!((m.k_d() - 0.1201).abs() < 1e-4, "k_D = {}", m.k_d());
        assert!((m.k_m0() - 3.60e-3).abs() < 1e-5, "k_M = {}", m.k_m0());
    }

    #[test]
    fn validation_names_the_key() {
        let mut p = PhysicsParams::paper();
        p.restitution = 1.5;
        assert_eq!(p.validate().unwrap_err().key, "restitution");
        p = PhysicsParams::paper();
        p.mass = f64::NAN;
        assert_eq!(p.validate().unwrap_err().key, "mass");
    }

    #[test]
    fn a_measured_lift_curve_is_checked_and_read_from_toml() {
        let p: PhysicsParams = toml::from_str(
            "mass = 0.0027\nradius = 0.02\ngravity = 9.81\nair_density = 1.29\ndrag_coefficient = 0.45\n\
             restitution = 0.9\nfriction = 0.2\n[lift]\nmodel = \"measured\"\ns = [0.2, 0.4]\nc_l = [0.19, 0.24]\n",
        )
        .unwrap();
        p.validate().unwrap();
        assert!((p.lift.c_l(0.3) - 0.215).abs() < 1e-12);
        let mut bad = p.clone();
        bad.lift = LiftModel::Measured {
            s: super::super::flight::LiftPoints::new(&[0.4, 0.2]).unwrap(),
            c_l: super::super::flight::LiftPoints::new(&[0.19, 0.24]).unwrap(),
        };
        assert_eq!(bad.validate().unwrap_err().key, "lift.s");
        bad.lift = LiftModel::Measured {
            s: super::super::flight::LiftPoints::new(&[0.2]).unwrap(),
            c_l: super::super::flight::LiftPoints::new(&[0.19, 0.24]).unwrap(),
        };
        assert_eq!(bad.validate().unwrap_err().key, "lift.c_l");
    }
}
