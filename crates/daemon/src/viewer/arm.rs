//! The arm as the viewer draws it: the KR 6 R900's links between the joint
//! frames of a joint vector (forward kinematics,
//! [`ArmGeometry::frames`]), each a cylinder, and a sphere at every joint
//! and at the TCP, placed in the table frame T by the calibrated base pose
//! (`[cell]` of `calib/robot.toml`). The sink draws the actual joints
//! (`AIPos`) and the commanded ones (`ASPos`, ahead of the actual by the
//! robot's dead time and lag) this way on `/view/robot`. Cold path.

use foxglove::messages as fm;
use topspin_core::calib::RobotFile;
use topspin_core::kinematics::{ArmGeometry, FRAMES, Joints};
use topspin_core::physics::Vec3;

use super::{IDENTITY, pose, quat_z_to, v3};

/// How one arm is drawn.
#[derive(Copy, Clone, Debug)]
pub(crate) struct ArmStyle {
    /// Link cylinders' diameter, m.
    pub link_diameter: f64,
    /// Joint spheres' diameter, m (the TCP's is a third of it).
    pub joint_diameter: f64,
    pub color: fm::Color,
}

/// The actual arm (`AIPos`): solid, KUKA orange.
pub(crate) const ACTUAL: ArmStyle =
    ArmStyle { link_diameter: 0.07, joint_diameter: 0.10, color: fm::Color { r: 1.0, g: 0.45, b: 0.0, a: 1.0 } };
/// The commanded arm (`ASPos`): a thinner translucent ghost, the colour of
/// the commanded TCP.
pub(crate) const COMMANDED: ArmStyle =
    ArmStyle { link_diameter: 0.05, joint_diameter: 0.07, color: fm::Color { r: 1.0, g: 0.2, b: 0.8, a: 0.3 } };

/// A link shorter than this is not drawn (its joints' spheres are), m.
const SHORTEST_LINK: f64 = 1e-6;

/// The calibration's arm and base pose.
#[derive(Clone, Debug)]
pub(crate) struct ArmView {
    geometry: ArmGeometry,
    robot: RobotFile,
}

impl ArmView {
    pub(crate) fn new(robot: &RobotFile) -> Self {
        ArmView { geometry: robot.arm().geometry, robot: robot.clone() }
    }

    /// The origins of `q`'s joint frames in T: the foot, A1..A6, the TCP.
    pub(crate) fn points(&self, q: &Joints) -> [Vec3; FRAMES] {
        self.geometry.frames(q).map(|f| self.robot.b_to_t(f.position))
    }

    /// Draws `q` (rad) into `e`, an entity in T: a cylinder per link (in
    /// order, foot to TCP; links shorter than [`SHORTEST_LINK`] left out),
    /// a sphere per frame origin ([`points`](Self::points) in order).
    /// Nothing for joints that are not finite.
    pub(crate) fn draw(&self, e: &mut fm::SceneEntity, q: &Joints, style: &ArmStyle) {
        if !q.0.iter().all(|x| x.is_finite()) {
            return;
        }
        let p = self.points(q);
        for w in p.windows(2) {
            let d = w[1] - w[0];
            let length = d.norm();
            if length < SHORTEST_LINK {
                continue;
            }
            e.cylinders.push(fm::CylinderPrimitive {
                pose: Some(pose((w[0] + w[1]) / 2.0, quat_z_to(d))),
                size: Some(v3(Vec3::new(style.link_diameter, style.link_diameter, length))),
                bottom_scale: 1.0,
                top_scale: 1.0,
                color: Some(style.color),
            });
        }
        for (k, &c) in p.iter().enumerate() {
            let d = if k == FRAMES - 1 { style.joint_diameter / 3.0 } else { style.joint_diameter };
            e.spheres.push(fm::SpherePrimitive {
                pose: Some(pose(c, IDENTITY)),
                size: Some(v3(Vec3::repeat(d))),
                color: Some(style.color),
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use topspin_core::calib::Calibration;

    fn from(p: &Option<fm::Pose>) -> (Vec3, fm::Quaternion) {
        let p = p.as_ref().expect("a pose");
        let v = p.position.as_ref().expect("a position");
        (Vec3::new(v.x, v.y, v.z), p.orientation.expect("an orientation"))
    }

    /// The cylinder's axis ends: its centre ∓ half its length along its z.
    fn ends(c: &fm::CylinderPrimitive) -> (Vec3, Vec3) {
        let (m, q) = from(&c.pose);
        let half = c.size.as_ref().unwrap().z / 2.0;
        let z = super::super::tests::rotate(q, Vec3::z());
        (m - z * half, m + z * half)
    }

    #[test]
    fn the_arm_stands_on_the_base_and_ends_at_the_tcp() {
        let cal = Calibration::default_cell();
        let view = ArmView::new(&cal.robot);
        let arm = cal.robot.arm();
        let home = cal.robot.home_joints(&arm).expect("home joints");
        for q in [home, Joints::kuka_home(), Joints::from_degrees([30.0, -60.0, 100.0, 20.0, -45.0, 10.0])] {
            let mut e = fm::SceneEntity::default();
            view.draw(&mut e, &q, &ACTUAL);
            let p = view.points(&q);
            // The foot at the calibrated base in T; the bat at the TCP.
            assert_eq!(p[0], Vec3::from(cal.robot.cell.base_in_table_xyz_m));
            assert_eq!(p[FRAMES - 1], cal.robot.b_to_t(arm.tcp(&q).position));
            assert_eq!(e.spheres.len(), FRAMES);
            for (s, want) in e.spheres.iter().zip(p) {
                assert_eq!(from(&s.pose).0, want);
            }
            // Every link of the KR 6 R900 has a length: one cylinder each,
            // from one frame's origin to the next.
            assert_eq!(e.cylinders.len(), FRAMES - 1);
            for (k, c) in e.cylinders.iter().enumerate() {
                let (a, b) = ends(c);
                assert!((a - p[k]).norm() < 1e-9 && (b - p[k + 1]).norm() < 1e-9, "link {k}: {a:?} {b:?}");
            }
        }
        // The home pose (calib [home]) in T: the TCP 1.70 m along x_T, 0.40 m up.
        let p = view.points(&home);
        assert!((p[FRAMES - 1] - Vec3::new(1.70, 0.0, 0.40)).norm() < 1e-9, "{:?}", p[FRAMES - 1]);
    }

    #[test]
    fn joints_that_are_not_finite_draw_nothing() {
        let view = ArmView::new(&Calibration::default_cell().robot);
        let mut e = fm::SceneEntity::default();
        view.draw(&mut e, &Joints([0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0]), &COMMANDED);
        assert!(e.cylinders.is_empty() && e.spheres.is_empty());
    }
}
