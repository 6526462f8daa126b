//! The table in its own frame T: playing surface z = 0 centred on the
//! origin, long axis x (opponent at −x, robot at +x), net at x = 0.

use serde::{Deserialize, Serialize};

use super::Vec3;

/// ITTF table geometry (overridable from `calib/table.toml`).
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Table {
    /// Playing surface length along x, m (ITTF: 2.74).
    pub length: f64,
    /// Playing surface width along y, m (ITTF: 1.525).
    pub width: f64,
    /// Net height above the surface, m (ITTF: 0.1525).
    pub net_height: f64,
    /// Net length along y including the posts' overhang, m (ITTF: 1.83).
    pub net_length: f64,
}

impl Default for Table {
    fn default() -> Self {
        Table { length: 2.74, width: 1.525, net_height: 0.1525, net_length: 1.83 }
    }
}

impl Table {
    /// x of the robot's end of the table.
    pub fn robot_end_x(&self) -> f64 {
        self.length / 2.0
    }

    /// x of the opponent's end of the table.
    pub fn opponent_end_x(&self) -> f64 {
        -self.length / 2.0
    }

    /// True when the point (x, y) lies on the playing surface.
    pub(crate) fn on_surface(&self, x: f64, y: f64) -> bool {
        x.abs() <= self.length / 2.0 && y.abs() <= self.width / 2.0
    }

    /// True when a ball of radius `r` centred at `p` touches the net (a thin
    /// vertical sheet at x = 0).
    pub(crate) fn touches_net(&self, p: &Vec3, r: f64) -> bool {
        p.x.abs() <= r && p.z <= self.net_height + r && p.z >= -r && p.y.abs() <= self.net_length / 2.0 + r
    }
}
