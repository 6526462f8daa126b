//! The ceiling-camera renderer: labelled synthetic ball crops, the ground
//! truth the logo methods are measured against (no real labelled images
//! exist for us).
//!
//! A ball of 40 mm (orange or white) with one dark circular logo printed on
//! it (body frame: the logo's centre is +z), flying as the simulator flies
//! it, seen by the pinhole camera of `calib/camera.toml` over a static table
//! (blue surface with a value-noise texture, the white centre line, the net's
//! tape). Each frame integrates `SUBFRAMES` samples per pixel spread over
//! the exposure (time-stratified, each at its own sub-pixel offset), so it
//! carries the motion blur of the translation and of the rotation; shading is
//! matt (Lambert under a ceiling light, hence the darker rim), the logo's
//! printed edge is soft, and sensor noise (read + shot) is added after the
//! gamma. The ball orientation is exp(\[ω\]×·t)·R₀ with R₀ uniformly random and
//! ω the pre-bounce spin. Seeded and deterministic: ball k of seed s is the
//! same whatever else is rendered.
//!
//! The camera side is simulated as well: the ball's circle is *measured* in
//! each rendered crop against the background ([`topspin_core::logo::measure_ball`]), and the
//! crop is cut around the measured centre (the TTI1 convention, see
//! [`crop_origin`]); the labels keep the true circle next to it.
//!
//! Cold path: rendering allocates freely.

use nalgebra::{Rotation3, UnitQuaternion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::truth::Flight;
use crate::{Setting, Truth};
use topspin_core::calib::CameraCalib;
use topspin_core::logo::BallView;
use topspin_core::logo::CropImage;
use topspin_core::logo::CropInput;
use topspin_core::logo::{Circle, measure_ball};
use topspin_core::physics::{Propagator, Vec3};
use topspin_core::time::Instant;
use topspin_core::wire::Crop as WireCrop;
pub use topspin_core::wire::crop_origin;

/// Side of a crop, px (the paper's crops are 60 × 60).
pub(crate) const CROP_SIZE: u32 = 60;

/// Samples per pixel over the exposure.
pub(crate) const SUBFRAMES: usize = 16;

/// Frames rendered per ball by default (the paper fits 10 to 30).
pub(crate) const DEFAULT_FRAMES: usize = 20;

/// Frames closer than this to the bounce are not used, s.
pub(crate) const BOUNCE_MARGIN: f64 = 0.002;

/// Width of the logo's soft printed edge, rad on the ball.
pub(crate) const LOGO_EDGE: f64 = 0.03;

/// The ball's colour.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum BallColour {
    /// An orange ball.
    Orange,
    /// A white ball.
    White,
}

impl BallColour {
    /// Both colours.
    pub const ALL: [BallColour; 2] = [BallColour::Orange, BallColour::White];

    /// Linear albedo (R, G, B).
    fn albedo(self) -> [f64; 3] {
        match self {
            BallColour::Orange => [0.90, 0.26, 0.035],
            BallColour::White => [0.82, 0.82, 0.78],
        }
    }

    /// The colour's name, lower case (`orange`, `white`), as it parses.
    pub fn name(self) -> &'static str {
        match self {
            BallColour::Orange => "orange",
            BallColour::White => "white",
        }
    }
}

impl std::str::FromStr for BallColour {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "orange" => Ok(BallColour::Orange),
            "white" => Ok(BallColour::White),
            other => Err(format!("unknown ball colour `{other}` (expected orange or white)")),
        }
    }
}

/// Linear albedo of the printed logo.
const LOGO_ALBEDO: [f64; 3] = [0.018, 0.018, 0.026];
/// The light and the sensor's noise: what a dataset varies to show that a
/// network trained under one setting generalises to another.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Conditions {
    /// Key light direction in the table frame (towards the light).
    pub light: Vec3,
    /// Ambient and key-light shares of the radiance.
    pub ambient: f64,
    /// Share of the radiance from the key light, times the cosine of its incidence.
    pub key: f64,
    /// Sensor read noise (8-bit units) and shot-noise gain.
    pub read_noise: f64,
    /// Shot-noise variance per unit of pixel value (8-bit units).
    pub shot_gain: f64,
}

impl Default for Conditions {
    /// The lab's ceiling light, a little towards +x and +y, and the
    /// Grasshopper3's noise at the paper's 0.25 ms exposure.
    fn default() -> Self {
        Conditions { light: Vec3::new(0.25, 0.15, 1.0), ambient: 0.22, key: 0.78, read_noise: 1.5, shot_gain: 0.02 }
    }
}

impl Conditions {
    /// Another lab: a light from the other side and lower, dimmer key,
    /// more ambient, twice the sensor noise (the held-out test set).
    pub fn other_lab() -> Self {
        Conditions { light: Vec3::new(-0.45, -0.30, 1.0), ambient: 0.30, key: 0.60, read_noise: 3.0, shot_gain: 0.04 }
    }
}

/// The scene: camera, ball, light.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The ceiling camera's calibration.
    pub cam: CameraCalib,
    /// The ball's colour.
    pub colour: BallColour,
    /// Sensor noise on (off gives the noise-free image, e.g. the
    /// background model).
    pub noise: bool,
    conditions: Conditions,
    light_c: Vec3,
}

/// Where the ball is and how it turns at one instant (table frame).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BallPose {
    /// Ball centre, m, table frame.
    pub pos: Vec3,
    /// Ball velocity, m/s, table frame.
    pub vel: Vec3,
    /// Body → table.
    pub orientation: Rotation3<f64>,
    /// Angular velocity, rad/s, table frame.
    pub spin: Vec3,
}

/// An RGB8 crop of the sensor image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Crop {
    /// Top-left pixel on the full sensor.
    pub x0: i64,
    /// Row of the top-left pixel on the full sensor.
    pub y0: i64,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Row-major RGB8, width · height · 3 bytes.
    pub rgb: Vec<u8>,
}

/// Ground truth of one frame.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FrameLabel {
    /// Camera frame index since the ball's launch.
    pub frame: u64,
    /// Capture time (middle of the exposure), s after launch.
    pub t: f64,
    /// The circle the camera side measured (what TTI1 carries).
    pub measured: Circle,
    /// The true circle (projected centre, equal-area radius).
    pub truth: Circle,
    /// Ball centre in the table frame, m.
    pub pos: Vec3,
    /// The logo's centre on the unit sphere, camera frame.
    pub logo_camera: Vec3,
    /// Its component towards the camera (the view frame's z): 1 facing the
    /// camera, 0 on the rim, −1 hidden behind.
    pub logo_facing: f64,
    /// The logo's centre lies on the visible hemisphere (facing > 0; the
    /// paper's visibility label).
    pub logo_visible: bool,
    /// Ball orientation, body → camera.
    pub camera_from_body: UnitQuaternion<f64>,
}

/// One rendered frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// The rendered crop.
    pub crop: Crop,
    /// Its ground truth.
    pub label: FrameLabel,
}

impl Frame {
    /// The crop as the logo detector takes it.
    pub fn crop_image(&self) -> CropImage<'_> {
        let c = &self.crop;
        CropImage::new(c.x0, c.y0, c.width as usize, c.height as usize, &c.rgb).expect("rendered crops are whole")
    }

    /// The crop with its capture time and measured circle (a sequence's input).
    pub fn crop_input(&self) -> CropInput<'_> {
        CropInput { t: self.label.t, crop: self.crop_image(), circle: self.label.measured }
    }

    /// The crop as a TTI1 datagram carries it: number `seq`, captured at
    /// `capture` on the receiver's clock, with the measured circle.
    pub fn wire_crop(&self, seq: u32, capture: Instant) -> WireCrop<'_> {
        let m = self.label.measured;
        WireCrop {
            seq,
            capture,
            u: m.u as f32,
            v: m.v as f32,
            radius: m.radius as f32,
            width: self.crop.width as u16,
            height: self.crop.height as u16,
            pixels: &self.crop.rgb,
        }
    }
}

/// The frames of one ball, consecutive camera frames before its bounce.
#[derive(Clone, Debug, PartialEq)]
pub struct Sequence {
    /// The ball's index `k` in the run.
    pub ball: usize,
    /// The ball's launcher setting.
    pub setting: Setting,
    /// The ball's colour.
    pub colour: BallColour,
    /// True spin before the bounce, rad/s, table frame.
    pub spin_table: Vec3,
    /// The frames, in capture order.
    pub frames: Vec<Frame>,
}

impl Sequence {
    /// Seconds from the first frame to the last (0 without frames).
    pub fn span(&self) -> f64 {
        match (self.frames.first(), self.frames.last()) {
            (Some(a), Some(b)) => b.label.t - a.label.t,
            _ => 0.0,
        }
    }
}

impl Scene {
    /// A scene under the default [`Conditions`], with sensor noise.
    pub fn new(cam: CameraCalib, colour: BallColour) -> Self {
        Self::with_conditions(cam, colour, Conditions::default())
    }

    /// A scene under `conditions`, with sensor noise.
    pub fn with_conditions(cam: CameraCalib, colour: BallColour, conditions: Conditions) -> Self {
        let light_c = cam.table_from_camera.inverse_transform_vector(&conditions.light.normalize());
        Scene { cam, colour, noise: true, conditions, light_c }
    }

    /// Texture of the table surface at (x, y) (table frame), linear RGB.
    fn table(&self, x: f64, y: f64) -> [f64; 3] {
        // The white lines and the net's top tape (seen from above).
        if y.abs() < 0.0015 || x.abs() < 0.0075 {
            return [0.80, 0.80, 0.78];
        }
        let n = 0.65 * value_noise(x / 0.006, y / 0.006) + 0.35 * value_noise(x / 0.03 + 17.0, y / 0.03 - 5.0);
        let k = 0.85 + 0.3 * n;
        [0.020 * k, 0.075 * k, 0.24 * k]
    }

    /// Radiance along the camera-frame unit ray `d` for the ball at `p`
    /// (camera frame, m) whose logo points along `logo` (camera frame):
    /// the ball where the ray meets it, the table behind otherwise.
    fn radiance(&self, d: &Vec3, ball: Option<(&Vec3, &Vec3)>) -> [f64; 3] {
        let r = self.cam.logo.ball_radius_m;
        if let Some((p, logo)) = ball {
            let b = d.dot(p);
            let disc = b * b - (p.norm_squared() - r * r);
            if disc >= 0.0 && b > 0.0 {
                let t = b - disc.sqrt();
                let n = (d * t - p) / r;
                let cos_rho = self.cam.logo_angular_radius().cos();
                let sin_rho = self.cam.logo_angular_radius().sin();
                // Angular distance past the logo's edge, to first order.
                let inside = (n.dot(logo) - cos_rho) / sin_rho;
                let cover = (0.5 + inside / LOGO_EDGE).clamp(0.0, 1.0);
                let a = self.colour.albedo();
                let shade = self.conditions.ambient + self.conditions.key * n.dot(&self.light_c).max(0.0);
                return std::array::from_fn(|c| (a[c] * (1.0 - cover) + LOGO_ALBEDO[c] * cover) * shade);
            }
        }
        // The table plane z = 0.
        let dt = self.cam.table_from_camera * d;
        let o = self.cam.position();
        if dt.z >= -1e-9 {
            return [0.05, 0.05, 0.05];
        }
        let s = -o.z / dt.z;
        let shade = self.conditions.ambient + self.conditions.key * self.conditions.light.normalize().z;
        self.table(o.x + s * dt.x, o.y + s * dt.y).map(|c| c * shade)
    }

    /// Renders the `width` × `height` block at (x0, y0): the ball at `pose`
    /// (None: the background alone), motion-blurred over the exposure.
    pub fn render(
        &self,
        pose: Option<&BallPose>,
        x0: i64,
        y0: i64,
        width: u32,
        height: u32,
        rng: &mut ChaCha8Rng,
    ) -> Crop {
        let (w, h) = (width as usize, height as usize);
        let exposure = self.cam.camera.exposure_s;
        let rtc = self.cam.table_from_camera;
        // Per sub-frame: ball centre and logo direction in the camera frame.
        let subs: Vec<(Vec3, Vec3, (f64, f64))> = (0..SUBFRAMES)
            .map(|s| {
                let tau = exposure * ((s as f64 + 0.5) / SUBFRAMES as f64 - 0.5);
                // Stratified sub-pixel offsets, decorrelated from time.
                let ox = ((s % 4) as f64 + 0.5) / 4.0 - 0.5;
                let oy = (((s / 4 + 3 * s) % 4) as f64 + 0.5) / 4.0 - 0.5;
                match pose {
                    Some(p) => {
                        let pos = p.pos + p.vel * tau;
                        let logo_t = Rotation3::new(p.spin * tau) * p.orientation * Vec3::z();
                        (
                            rtc.inverse_transform_vector(&(pos - self.cam.position())),
                            rtc.inverse_transform_vector(&logo_t),
                            (ox, oy),
                        )
                    }
                    None => (Vec3::zeros(), Vec3::zeros(), (ox, oy)),
                }
            })
            .collect();
        let mut rgb = vec![0u8; 3 * w * h];
        for row in 0..h {
            for col in 0..w {
                let mut acc = [0.0f64; 3];
                for sub in &subs {
                    let (p, logo, (ox, oy)) = sub;
                    let u = (x0 + col as i64) as f64 + ox;
                    let v = (y0 + row as i64) as f64 + oy;
                    let d = self.cam.ray(u, v);
                    let ball = pose.map(|_| (p, logo));
                    let l = self.radiance(&d, ball);
                    for c in 0..3 {
                        acc[c] += l[c];
                    }
                }
                for c in 0..3 {
                    let lin = (acc[c] / SUBFRAMES as f64).clamp(0.0, 1.0);
                    let mut val = 255.0 * lin.powf(1.0 / 2.2);
                    if self.noise {
                        let c = &self.conditions;
                        let sigma = (c.read_noise * c.read_noise + c.shot_gain * val).sqrt();
                        let z: f64 = StandardNormal.sample(rng);
                        val += sigma * z;
                    }
                    rgb[3 * (row * w + col) + c] = val.round().clamp(0.0, 255.0) as u8;
                }
            }
        }
        Crop { x0, y0, width, height, rgb }
    }

    /// The noise-free background of a block (the camera side's model of the
    /// empty scene).
    pub fn background(&self, x0: i64, y0: i64, width: u32, height: u32) -> Crop {
        let quiet = Scene { noise: false, ..self.clone() };
        quiet.render(None, x0, y0, width, height, &mut ChaCha8Rng::seed_from_u64(0))
    }

    /// Renders one frame of the ball at `pose`: the crop around the ball
    /// as the camera side would cut it (around its measured centre) and the
    /// labels. `None` when the crop would leave the ROI or the ball cannot
    /// be measured.
    pub fn frame(&self, pose: &BallPose, frame: u64, t: f64, rng_seed: (u64, u64)) -> Option<Frame> {
        let r = self.cam.logo.ball_radius_m;
        let p_c = self.cam.to_camera(&pose.pos);
        let truth_view = BallView::of_sphere(&self.cam, &p_c, r)?;
        let truth = Circle { u: truth_view.u, v: truth_view.v, radius: truth_view.radius };
        let mut origin = crop_origin(truth.u, truth.v, CROP_SIZE, CROP_SIZE);
        let mut measured = None;
        let mut crop = None;
        // Cut around the true centre, measure, and cut again around the
        // measured centre where that moves the crop (same noise draw).
        for _ in 0..2 {
            if !self.cam.block_in_roi(origin.0, origin.1, CROP_SIZE, CROP_SIZE) {
                return None;
            }
            let mut rng = ChaCha8Rng::seed_from_u64(rng_seed.0);
            rng.set_stream(rng_seed.1);
            let c = self.render(Some(pose), origin.0, origin.1, CROP_SIZE, CROP_SIZE, &mut rng);
            let bg = self.background(origin.0, origin.1, CROP_SIZE, CROP_SIZE);
            let m = measure_ball(&c.rgb, &bg.rgb, CROP_SIZE as usize, CROP_SIZE as usize, origin.0, origin.1)?;
            let want = crop_origin(m.u, m.v, CROP_SIZE, CROP_SIZE);
            measured = Some(m);
            crop = Some(c);
            if want == origin {
                break;
            }
            origin = want;
        }
        let (crop, measured) = (crop?, measured?);
        if crop_origin(measured.u, measured.v, CROP_SIZE, CROP_SIZE) != (crop.x0, crop.y0) {
            return None;
        }
        let camera_from_body = self.cam.table_from_camera.inverse() * pose.orientation;
        let logo_camera = camera_from_body * Vec3::z();
        let toward = -p_c.normalize();
        let logo_facing = logo_camera.dot(&toward);
        let logo_visible = logo_facing > 0.0;
        Some(Frame {
            crop,
            label: FrameLabel {
                frame,
                t,
                measured,
                truth,
                pos: pose.pos,
                logo_camera,
                logo_facing,
                logo_visible,
                camera_from_body: UnitQuaternion::from_rotation_matrix(&camera_from_body),
            },
        })
    }
}

/// Fewest frames for a rendered sequence to count as filmed (the logo
/// estimators need this many crops of one flight).
pub const MIN_FILMED_FRAMES: usize = 10;

/// Options of a rendered sequence.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SequenceOptions {
    /// Frames wanted (the first consecutive in-ROI frames before the bounce).
    pub frames: usize,
}

impl Default for SequenceOptions {
    fn default() -> Self {
        SequenceOptions { frames: DEFAULT_FRAMES }
    }
}

/// A uniformly random rotation (Shoemake's method via a normalised 4-D
/// Gaussian).
fn random_rotation(rng: &mut impl Rng) -> Rotation3<f64> {
    let q: [f64; 4] = std::array::from_fn(|_| StandardNormal.sample(rng));
    let q = nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]);
    UnitQuaternion::from_quaternion(q).to_rotation_matrix()
}

/// The random stream of ball `k`'s rendering (apart from the simulator's
/// launcher and tracker streams 2k and 2k + 1).
fn render_stream(k: usize, colour: BallColour) -> u64 {
    (1u64 << 40) + 2 * k as u64 + (colour == BallColour::White) as u64
}

/// Renders ball `k` of the run `seed` (the simulator's flight `truth`):
/// the first `opts.frames` consecutive camera frames in which the ball is
/// inside the ROI before its bounce. The camera's frame phase and the
/// ball's initial orientation are drawn from the ball's own stream. The
/// result may hold fewer frames (the ball left the ROI, bounced, or never
/// flew through the filmed strip).
pub fn render_sequence(
    scene: &Scene,
    truth: &Truth,
    prop: &Propagator,
    seed: u64,
    k: usize,
    opts: &SequenceOptions,
) -> Sequence {
    let stream = render_stream(k, scene.colour);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    let dt = scene.cam.frame_period();
    let phase = rng.random::<f64>() * dt;
    let r0 = random_rotation(&mut rng);
    let spin = Vec3::from(truth.spin);
    let t_end = truth.bounce.map(|b| b.t - BOUNCE_MARGIN).unwrap_or(truth.end_t);
    let launch = truth.to_launch();
    let mut flight = Flight::new(&launch, prop);
    let mut frames = Vec::new();
    let mut i = 0u64;
    loop {
        let t = phase + i as f64 * dt;
        if t > t_end || frames.len() >= opts.frames {
            break;
        }
        let s = flight.at(t);
        let turn = Rotation3::new(spin * t);
        let pose = BallPose { pos: s.pos, vel: s.vel, orientation: turn * r0, spin };
        // Per frame noise stream: the ball's seed, a stream of its own.
        let noise = (seed ^ 0x9e37_79b9_7f4a_7c15, (stream << 16) + i);
        match scene.frame(&pose, i, t, noise) {
            Some(f) => frames.push(f),
            // Consecutive frames only: stop when the ball leaves the ROI.
            None if !frames.is_empty() => break,
            None => {}
        }
        i += 1;
    }
    Sequence { ball: k, setting: truth.setting, colour: scene.colour, spin_table: spin, frames }
}

/// Smooth value noise in [0, 1] on a unit lattice (hash of the corners,
/// smoothstep blend). Deterministic, no state.
fn value_noise(x: f64, y: f64) -> f64 {
    let (xi, yi) = (x.floor(), y.floor());
    let (fx, fy) = (x - xi, y - yi);
    let h = |i: f64, j: f64| -> f64 {
        let mut z = (i as i64 as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (j as i64 as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        z ^= z >> 29;
        z = z.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z ^= z >> 32;
        (z >> 11) as f64 / (1u64 << 53) as f64
    };
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (s(fx), s(fy));
    let a = h(xi, yi) + (h(xi + 1.0, yi) - h(xi, yi)) * sx;
    let b = h(xi, yi + 1.0) + (h(xi + 1.0, yi + 1.0) - h(xi, yi + 1.0)) * sx;
    a + (b - a) * sy
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{TrackerModel, simulate_ball};
    use topspin_core::calib::Calibration;

    #[test]
    fn a_sequence_is_deterministic_and_labelled() {
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let scene = Scene::new(CameraCalib::default_camera(), BallColour::Orange);
        // Find a ball that flies through the filmed strip.
        let mut found = None;
        for k in 0..12 {
            let b =
                simulate_ball(3, k, Setting::ALL[7], &prop, cal.strike.hit_plane_x, &TrackerModel::default()).unwrap();
            let seq = render_sequence(&scene, &b.truth, &prop, 3, k, &SequenceOptions { frames: 4 });
            if seq.frames.len() == 4 {
                found = Some((b, seq));
                break;
            }
        }
        let (b, seq) = found.expect("a ball in the strip");
        let again = render_sequence(&scene, &b.truth, &prop, 3, b.index, &SequenceOptions { frames: 4 });
        assert_eq!(seq, again);
        for f in &seq.frames {
            let l = &f.label;
            assert_eq!(f.crop.rgb.len(), (3 * CROP_SIZE * CROP_SIZE) as usize);
            assert!((20.0..27.0).contains(&l.truth.radius), "{l:?}");
            // The camera side's circle is close to the truth.
            assert!((l.measured.u - l.truth.u).abs() < 1.0 && (l.measured.v - l.truth.v).abs() < 1.0, "{l:?}");
            assert!((l.measured.radius - l.truth.radius).abs() < 1.0, "{l:?}");
            assert!((l.logo_camera.norm() - 1.0).abs() < 1e-9);
            assert!((l.camera_from_body * Vec3::z() - l.logo_camera).norm() < 1e-9);
        }
        // Consecutive frames at 380 Hz.
        let dt = seq.frames[1].label.t - seq.frames[0].label.t;
        assert!((dt - 1.0 / 380.0).abs() < 1e-12);
        assert_eq!(seq.frames[1].label.frame, seq.frames[0].label.frame + 1);
    }
}
