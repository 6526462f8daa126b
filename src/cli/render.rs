//! `topspin render`: labelled synthetic ceiling-camera crops of simulated
//! launcher balls ([`topspin_sim::render`]), written as PNG + CSV (`--out DIR`)
//! and/or streamed live as TTI1 datagrams (`--to ADDR`). Deterministic in
//! `--seed`; only the pacing of the stream follows the wall clock.
//!
//! `--out DIR` writes, per filmed ball, a folder `ball-NNN-COLOUR/` with
//! `frame-KK.png`, `frames.csv` (the input of `topspin logo`) and
//! `truth.json`, and one `labels.csv` over all frames (paths relative to
//! DIR) for datasets. Columns of both CSVs:
//!
//! `file,ball,setting,colour,frame,t,u,v,radius,true_u,true_v,true_radius,
//! logo_visible,logo_facing,logo_x,logo_y,logo_z,q_w,q_x,q_y,q_z,x,y,z,
//! spin_x,spin_y,spin_z,view_x,view_y,view_z` — t in s after launch; u, v, radius the circle the
//! camera side measured (full-sensor px), `true_*` the projected truth;
//! the logo's centre on the unit sphere and the orientation (body → camera
//! quaternion; the logo is the body's +z) in the camera frame; the ball
//! centre and the spin in the table frame; `view_*` the logo's centre in
//! the view frame of the measured circle ([`topspin_core::logo::BallView`]: z towards
//! the camera, x along image u, y image up), the CNN's training target.

use std::fmt::Write as _;
use std::io::Write as _;
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::time::Duration;
use topspin_daemon::calib_files::CalibDir;

use serde_json::json;

use super::args::{Colours, Settings};
use super::bad;
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::logo::BallView;
use topspin_core::physics::{Vec3, rad_to_rps};
use topspin_core::time::Instant;
use topspin_core::wire::{CROP_MAX_LEN, Crop};
use topspin_sim::render::MIN_FILMED_FRAMES;
use topspin_sim::render::{Conditions, Frame, Scene, Sequence, SequenceOptions, render_sequence};
use topspin_sim::{TrackerModel, simulate_ball};

/// Where the live stream's capture clock starts before the first ball, s.
pub const STREAM_LEAD: f64 = 0.2;
/// Seconds between balls in the live stream.
pub const STREAM_GAP: f64 = 1.0;

#[derive(Debug, clap::Args)]
#[command(group = clap::ArgGroup::new("sink").required(true).multiple(true).args(["out", "to"]))]
pub struct RenderArgs {
    /// Write the PNG crops and labels into DIR.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Stream the crops as TTI1 datagrams to ADDR (host:port) in real time.
    #[arg(long, value_name = "ADDR")]
    pub to: Option<String>,
    /// Local address for the stream's socket.
    #[arg(long, value_name = "ADDR", default_value = "0.0.0.0:0")]
    pub bind: String,
    /// Filmed balls per colour (balls that fly outside the camera's strip
    /// are skipped and named).
    #[arg(long, default_value_t = 10)]
    pub balls: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// `all`, or comma-separated launcher settings; ball k takes setting
    /// k mod their number.
    #[arg(long, default_value = "all")]
    pub setting: Settings,
    /// Ball colours.
    #[arg(long, value_enum, default_value_t = Colours::Orange)]
    pub colour: Colours,
    /// Consecutive frames per ball (before the bounce, inside the ROI).
    #[arg(long, default_value_t = 20)]
    pub frames_per_ball: usize,
    /// Calibration folder (camera.toml and the others).
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
    /// Light and sensor noise: `lab` (the default scene) or `other-lab`
    /// (light from the other side, dimmer, twice the noise: held-out tests).
    #[arg(long, value_enum, default_value = "lab")]
    pub conditions: ConditionsArg,
}

/// `--conditions`.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ConditionsArg {
    Lab,
    OtherLab,
}

impl ConditionsArg {
    pub fn conditions(self) -> Conditions {
        match self {
            ConditionsArg::Lab => Conditions::default(),
            ConditionsArg::OtherLab => Conditions::other_lab(),
        }
    }
}

pub fn run(a: RenderArgs) -> anyhow::Result<()> {
    let cal = Calibration::load(a.calib.as_deref()).map_err(|e| bad(e.to_string()))?;
    let cam = CameraCalib::load(a.calib.as_deref()).map_err(|e| bad(e.to_string()))?;
    let settings = a.setting.0.clone();
    let colours = a.colour.list();
    if a.frames_per_ball < MIN_FILMED_FRAMES || a.frames_per_ball > 1000 {
        return Err(bad(format!("--frames-per-ball {} must be in {MIN_FILMED_FRAMES}..=1000", a.frames_per_ball)));
    }
    let prop = cal.propagator();
    let mut sequences = Vec::new();
    for colour in colours {
        let scene = Scene::with_conditions(cam.clone(), colour, a.conditions.conditions());
        let mut got = 0;
        let mut k = 0;
        while got < a.balls && k < 20 * a.balls + 20 {
            let setting = settings[k % settings.len()];
            let ball = simulate_ball(a.seed, k, setting, &prop, cal.strike.hit_plane_x, &TrackerModel::default())
                .map_err(|e| bad(e.to_string()))?;
            let seq =
                render_sequence(&scene, &ball.truth, &prop, a.seed, k, &SequenceOptions { frames: a.frames_per_ball });
            if seq.frames.len() >= MIN_FILMED_FRAMES {
                println!(
                    "ball {k:03} {:<6} {:<15} {:2} frames, spin {:5.1} rps, logo seen (truth) in {}",
                    colour.name(),
                    setting,
                    seq.frames.len(),
                    ball.truth.spin_rps,
                    seq.frames.iter().filter(|f| f.label.logo_visible).count()
                );
                sequences.push(seq);
                got += 1;
            } else {
                println!(
                    "ball {k:03} {:<6} {:<15} not filmed ({} frames in the camera's strip)",
                    colour.name(),
                    setting,
                    seq.frames.len()
                );
            }
            k += 1;
        }
    }
    if let Some(dir) = &a.out {
        write_dataset(dir, a.seed, &cam, &sequences)?;
    }
    if let Some(to) = &a.to {
        stream(to, &a.bind, &sequences)?;
    }
    Ok(())
}

fn folder_name(s: &Sequence) -> String {
    format!("ball-{:03}-{}", s.ball, s.colour.name())
}

const HEADER: &str = "file,ball,setting,colour,frame,t,u,v,radius,true_u,true_v,true_radius,logo_visible,logo_facing,\
logo_x,logo_y,logo_z,q_w,q_x,q_y,q_z,x,y,z,spin_x,spin_y,spin_z,view_x,view_y,view_z";

fn label_line(cam: &CameraCalib, file: &str, s: &Sequence, f: &Frame) -> String {
    let l = &f.label;
    let view = BallView::new(cam, l.measured.u, l.measured.v, l.measured.radius)
        .map(|v| v.to_view(&l.logo_camera))
        .unwrap_or(Vec3::new(f64::NAN, f64::NAN, f64::NAN));
    let q = l.camera_from_body.quaternion();
    let w = s.spin_table;
    let mut line = String::new();
    let _ = writeln!(
        line,
        "{file},{},{},{},{},{:.9},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.4},{:.4},{:.4},{:.6},{:.6},{:.6}",
        s.ball,
        s.setting,
        s.colour.name(),
        l.frame,
        l.t,
        l.measured.u,
        l.measured.v,
        l.measured.radius,
        l.truth.u,
        l.truth.v,
        l.truth.radius,
        l.logo_visible as u8,
        l.logo_facing,
        l.logo_camera.x,
        l.logo_camera.y,
        l.logo_camera.z,
        q.w,
        q.i,
        q.j,
        q.k,
        l.pos.x,
        l.pos.y,
        l.pos.z,
        w.x,
        w.y,
        w.z,
        view.x,
        view.y,
        view.z
    );
    line
}

/// Writes an 8-bit RGB PNG.
pub fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> anyhow::Result<()> {
    let file = std::fs::File::create(path).map_err(|e| bad(format!("cannot write {}: {e}", path.display())))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header()?;
    w.write_image_data(rgb)?;
    w.finish()?;
    Ok(())
}

fn write_dataset(dir: &Path, seed: u64, cam: &CameraCalib, sequences: &[Sequence]) -> anyhow::Result<()> {
    let io = |what: &Path, e: std::io::Error| bad(format!("cannot write {}: {e}", what.display()));
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    let mut labels = String::from(HEADER);
    labels.push('\n');
    for s in sequences {
        let name = folder_name(s);
        let sub = dir.join(&name);
        std::fs::create_dir_all(&sub).map_err(|e| io(&sub, e))?;
        let mut frames = String::from(HEADER);
        frames.push('\n');
        for (i, f) in s.frames.iter().enumerate() {
            let file = format!("frame-{i:02}.png");
            write_png(&sub.join(&file), f.crop.width, f.crop.height, &f.crop.rgb)?;
            frames.push_str(&label_line(cam, &file, s, f));
            labels.push_str(&label_line(cam, &format!("{name}/{file}"), s, f));
        }
        let path = sub.join("frames.csv");
        std::fs::write(&path, frames).map_err(|e| io(&path, e))?;
        let w = s.spin_table;
        let w_cam = cam.table_from_camera.inverse_transform_vector(&w);
        let truth = json!({
            "ball": s.ball,
            "seed": seed,
            "setting": s.setting,
            "colour": s.colour.name(),
            "spin": [w.x, w.y, w.z],
            "spin_rps": [rad_to_rps(w.x), rad_to_rps(w.y), rad_to_rps(w.z)],
            "spin_camera": [w_cam.x, w_cam.y, w_cam.z],
            "frames": s.frames.len(),
        });
        let path = sub.join("truth.json");
        std::fs::write(&path, serde_json::to_string_pretty(&truth)? + "\n").map_err(|e| io(&path, e))?;
    }
    let path = dir.join("labels.csv");
    std::fs::write(&path, labels).map_err(|e| io(&path, e))?;
    Ok(())
}

/// Sends every crop as a TTI1 datagram at its capture time on the wall
/// clock (ball j launched at `STREAM_LEAD + j · STREAM_GAP`).
fn stream(to: &str, bind: &str, sequences: &[Sequence]) -> anyhow::Result<()> {
    let socket = UdpSocket::bind(bind).map_err(|e| bad(format!("--bind {bind}: {e}")))?;
    socket.connect(to).map_err(|e| bad(format!("--to {to}: {e}")))?;
    let epoch = topspin_daemon::clock::now();
    let mut buf = vec![0u8; CROP_MAX_LEN];
    let (mut seq, mut sent) = (0u32, 0usize);
    for (j, s) in sequences.iter().enumerate() {
        for f in &s.frames {
            let capture = STREAM_LEAD + j as f64 * STREAM_GAP + f.label.t;
            if let Some(wait) = Duration::from_secs_f64(capture)
                .checked_sub(std::time::Duration::from_secs_f64(topspin_daemon::clock::secs_since(epoch)))
            {
                std::thread::sleep(wait);
            }
            let crop = Crop {
                seq,
                capture: Instant::from_secs_f64(capture),
                u: f.label.measured.u as f32,
                v: f.label.measured.v as f32,
                radius: f.label.measured.radius as f32,
                width: f.crop.width as u16,
                height: f.crop.height as u16,
                pixels: &f.crop.rgb,
            };
            let n = crop.emit(&mut buf)?;
            match socket.send(&buf[..n]) {
                Ok(_) => sent += 1,
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {}
                Err(e) => return Err(anyhow::Error::new(e).context(format!("sending to {to}"))),
            }
            seq = seq.wrapping_add(1);
        }
    }
    let _ = writeln!(std::io::stderr().lock(), "topspin render: sent {sent} of {seq} TTI1 datagrams to {to}");
    Ok(())
}
