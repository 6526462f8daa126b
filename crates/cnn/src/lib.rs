//! The logo CNN's engine (paper §III) through `ort`: loads the ONNX model
//! of `tools/logo_cnn/train.py` and runs it on 60 × 60 crops, answering
//! with [`CnnOutput`]s (the contract is `topspin_core::logo::LogoNetwork`).
//!
//! Two backends, chosen once per process (ONNX Runtime's API pointer is
//! process-global): the embedded pure-Rust **tract** (`ort-tract`), which
//! needs no setup, and **ONNX Runtime** itself, loaded at run time from a
//! shared library (the one inside the PyPI wheel `onnxruntime`), which is
//! faster. [`Backend::Auto`] takes ONNX Runtime when `ORT_DYLIB_PATH` names
//! a library, tract otherwise.
//!
//! Start from [`LogoCnn::load`]; [`default_model`] finds the committed model.
//! Inference allocates inside the backend (output tensors), so it runs on
//! the logo thread only, never on a hot thread; our own buffers are sized
//! at load time.
//!
//! `DESIGN §n` in these docs cites section n of `docs/design.md`.

#![warn(missing_docs)]
#![deny(unreachable_pub)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use nalgebra::{Quaternion, UnitQuaternion};
use ort::session::Session;
use ort::session::builder::GraphOptimizationLevel;
use ort::value::TensorRef;

use topspin_core::calib::CameraCalib;
use topspin_core::logo::Circle;
pub use topspin_core::logo::{CnnOutput, INPUT_LEN, INPUT_SIZE, LogoNetwork, MAX_BATCH, VISIBLE_THRESHOLD};
use topspin_core::logo::{LogoSample, RotationFit, RotationFitConfig, RotationFitError, fit_rotation};

/// Environment variable naming the ONNX Runtime shared library.
const ORT_DYLIB_ENV: &str = "ORT_DYLIB_PATH";

/// Which inference engine runs the model.
#[derive(Clone, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Backend {
    /// ONNX Runtime when `ORT_DYLIB_PATH` names a library, tract otherwise.
    Auto,
    /// The embedded pure-Rust engine (no setup).
    Tract,
    /// ONNX Runtime from the shared library named by `ORT_DYLIB_PATH`.
    #[value(name = "onnxruntime")]
    #[serde(rename = "onnxruntime")]
    OnnxRuntime,
}

impl Backend {
    /// The name used on the command line and in configuration files.
    pub fn name(&self) -> &'static str {
        match self {
            Backend::Auto => "auto",
            Backend::Tract => "tract",
            Backend::OnnxRuntime => "onnxruntime",
        }
    }
}

/// Why the CNN cannot run.
#[derive(Debug, thiserror::Error)]
pub enum CnnError {
    /// ONNX Runtime was asked for but `ORT_DYLIB_PATH` is unset or empty.
    #[error(
        "ONNX Runtime requested but {ORT_DYLIB_ENV} names no library (install the `onnxruntime` wheel, see README)"
    )]
    NoDylib,
    /// The ONNX Runtime shared library could not be loaded.
    #[error("cannot load ONNX Runtime from {path}: {msg}")]
    Dylib {
        /// The library path from `ORT_DYLIB_PATH`.
        path: PathBuf,
        /// The loader's message.
        msg: String,
    },
    /// The process's engine was already set up with another backend.
    #[error("the inference backend is already {active}; one process uses one backend")]
    BackendConflict {
        /// Name of the backend in use ([`Backend::name`]).
        active: &'static str,
    },
    /// The model file is missing, does not load, or lacks the
    /// `visibility` / `quaternion` outputs.
    #[error("{path}: {msg}")]
    Model {
        /// The model file.
        path: PathBuf,
        /// What went wrong.
        msg: String,
    },
    /// Inference failed (or was given inputs of the wrong size); the message.
    #[error("inference failed: {0}")]
    Run(String),
    /// A crop is not 60 × 60 RGB8.
    #[error("crop {index}: {len} bytes, expected a 60 × 60 RGB crop ({} bytes)", INPUT_SIZE * INPUT_SIZE * 3)]
    BadCrop {
        /// Index of the crop in the call's input.
        index: usize,
        /// Its length, bytes.
        len: usize,
    },
}

struct Engine {
    backend: Backend,
    env: ort::environment::Environment,
}

/// The process's one inference engine (its backend is process-global).
static ENGINE: OnceLock<Result<Engine, String>> = OnceLock::new();

fn dylib_from_env() -> Option<PathBuf> {
    std::env::var_os(ORT_DYLIB_ENV).filter(|s| !s.is_empty()).map(PathBuf::from)
}

/// The process's inference engine, set up on first use with `wanted`.
fn engine(wanted: &Backend) -> Result<&'static Engine, CnnError> {
    let resolved = match wanted {
        Backend::Auto if dylib_from_env().is_some() => Backend::OnnxRuntime,
        Backend::Auto => Backend::Tract,
        b => b.clone(),
    };
    let e = ENGINE.get_or_init(|| {
        let init = match resolved {
            Backend::OnnxRuntime => {
                let path = dylib_from_env().ok_or_else(|| CnnError::NoDylib.to_string())?;
                ort::init_from(&path)
                    .map_err(|e| CnnError::Dylib { path: path.clone(), msg: e.to_string() }.to_string())?
            }
            _ => {
                ort::set_api(ort_tract::api());
                ort::init()
            }
        };
        let env = init.with_name("topspin-logo").build().map_err(|e| e.to_string())?;
        Ok(Engine { backend: resolved.clone(), env })
    });
    let e = e.as_ref().map_err(|msg| {
        if msg == &CnnError::NoDylib.to_string() { CnnError::NoDylib } else { CnnError::Run(msg.clone()) }
    })?;
    if e.backend != resolved {
        return Err(CnnError::BackendConflict { active: e.backend.name() });
    }
    Ok(e)
}

/// A loaded model, its session and its input buffer.
pub struct LogoCnn {
    session: Session,
    backend: Backend,
    model: PathBuf,
    input: Vec<f32>,
}

impl std::fmt::Debug for LogoCnn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogoCnn").field("backend", &self.backend).field("model", &self.model).finish()
    }
}

impl LogoCnn {
    /// Loads `model` on `backend` (one intra-op thread: the logo thread
    /// has one core, and two threads doubled the tail under contention).
    pub fn load(model: &Path, backend: &Backend) -> Result<Self, CnnError> {
        let engine = engine(backend)?;
        let bad = |e: ort::Error| CnnError::Model { path: model.to_path_buf(), msg: e.to_string() };
        if !model.is_file() {
            return Err(CnnError::Model { path: model.to_path_buf(), msg: "no such file".into() });
        }
        // Optimisation matters most for tract: unoptimised it runs the
        // graph as parsed, ~20× slower.
        let mut builder = Session::builder(&engine.env)
            .map_err(bad)?
            .with_optimization_level(GraphOptimizationLevel::Level3)
            .map_err(|e| bad(e.into()))?;
        if engine.backend == Backend::OnnxRuntime {
            builder = builder.with_intra_threads(1).map_err(|e| bad(e.into()))?;
            builder = builder.with_inter_threads(1).map_err(|e| bad(e.into()))?;
        }
        let session = builder.commit_from_file(model).map_err(bad)?;
        let names: Vec<&str> = session.outputs().iter().map(|o| o.name()).collect();
        for want in ["visibility", "quaternion"] {
            if !names.contains(&want) {
                return Err(CnnError::Model {
                    path: model.to_path_buf(),
                    msg: format!("no output `{want}` (outputs: {names:?}); not a topspin logo model"),
                });
            }
        }
        Ok(LogoCnn {
            session,
            backend: engine.backend.clone(),
            model: model.to_path_buf(),
            input: vec![0.0; MAX_BATCH * INPUT_LEN],
        })
    }

    /// The backend that runs this model.
    pub fn backend(&self) -> &Backend {
        &self.backend
    }

    /// The crops run per call of the backend: [`MAX_BATCH`] on ONNX
    /// Runtime; one on tract, whose plan is optimised for the first shape
    /// it sees (a batch of five took 1.4× five single crops).
    pub fn batch(&self) -> usize {
        if self.backend == Backend::Tract { 1 } else { MAX_BATCH }
    }

    /// Runs crops (60 × 60 RGB8, row-major) in batches of
    /// [`batch`](Self::batch); `out[i]` is crop `i`'s answer.
    pub fn infer(&mut self, crops: &[&[u8]], out: &mut [CnnOutput]) -> Result<(), CnnError> {
        assert!(out.len() >= crops.len(), "one output per crop");
        let batch = self.batch();
        for (start, chunk) in crops.chunks(batch).enumerate().map(|(k, c)| (k * batch, c)) {
            self.infer_batch(start, chunk, &mut out[start..start + chunk.len()])?;
        }
        Ok(())
    }

    /// Runs the network on inputs already in its layout (f32 NCHW in
    /// [0, 1], [`INPUT_LEN`] per crop, up to [`MAX_BATCH`] crops).
    pub fn infer_floats(&mut self, x: &[f32], out: &mut [CnnOutput]) -> Result<(), CnnError> {
        let n = x.len() / INPUT_LEN;
        if !x.len().is_multiple_of(INPUT_LEN) || n == 0 || n > MAX_BATCH || out.len() < n {
            return Err(CnnError::Run(format!("{} floats is not 1..={MAX_BATCH} crops", x.len())));
        }
        self.input[..x.len()].copy_from_slice(x);
        self.run(n, out)
    }

    fn infer_batch(&mut self, first: usize, crops: &[&[u8]], out: &mut [CnnOutput]) -> Result<(), CnnError> {
        let plane = INPUT_SIZE * INPUT_SIZE;
        for (i, rgb) in crops.iter().enumerate() {
            if rgb.len() != 3 * plane {
                return Err(CnnError::BadCrop { index: first + i, len: rgb.len() });
            }
            let dst = &mut self.input[i * INPUT_LEN..(i + 1) * INPUT_LEN];
            for (p, px) in rgb.chunks_exact(3).enumerate() {
                for c in 0..3 {
                    dst[c * plane + p] = px[c] as f32 * (1.0 / 255.0);
                }
            }
        }
        self.run(crops.len(), out)
    }

    fn run(&mut self, n: usize, out: &mut [CnnOutput]) -> Result<(), CnnError> {
        let shape = [n, 3, INPUT_SIZE, INPUT_SIZE];
        let input = TensorRef::from_array_view((shape, &self.input[..n * INPUT_LEN]))
            .map_err(|e| CnnError::Run(e.to_string()))?;
        let outputs = self.session.run(ort::inputs!["crops" => input]).map_err(|e| CnnError::Run(e.to_string()))?;
        let (_, vis) = outputs["visibility"].try_extract_tensor::<f32>().map_err(|e| CnnError::Run(e.to_string()))?;
        let (_, quat) = outputs["quaternion"].try_extract_tensor::<f32>().map_err(|e| CnnError::Run(e.to_string()))?;
        if vis.len() != n || quat.len() != 4 * n {
            return Err(CnnError::Run(format!("output shapes {} and {} for {n} crops", vis.len(), quat.len())));
        }
        for i in 0..n {
            let q = &quat[4 * i..4 * i + 4];
            let q = Quaternion::new(q[0] as f64, q[1] as f64, q[2] as f64, q[3] as f64);
            out[i] = CnnOutput {
                visibility: if vis[i].is_finite() { vis[i] } else { 0.0 },
                orientation: UnitQuaternion::try_new(q, 1e-9).unwrap_or_else(UnitQuaternion::identity),
            };
        }
        Ok(())
    }
}

impl LogoNetwork for LogoCnn {
    fn engine_name(&self) -> &'static str {
        self.backend.name()
    }

    fn infer_crops(&mut self, crops: &[&[u8]], out: &mut [CnnOutput]) -> Result<(), String> {
        self.infer(crops, out).map_err(|e| e.to_string())
    }
}

/// The CNN's rotation fit over one ball's crops (time, measured circle,
/// 60 × 60 RGB8 pixels), in the table frame; with the count of crops in
/// which the network saw the logo.
pub fn fit_crops(
    net: &mut LogoCnn,
    cam: &CameraCalib,
    crops: &[(f64, Circle, &[u8])],
    cfg: &RotationFitConfig,
) -> Result<(usize, Result<RotationFit, RotationFitError>), CnnError> {
    let pixels: Vec<&[u8]> = crops.iter().map(|c| c.2).collect();
    let mut out = vec![CnnOutput::default(); crops.len()];
    net.infer(&pixels, &mut out)?;
    let samples: Vec<LogoSample> = crops.iter().zip(&out).map(|(c, o)| o.sample(cam, c.1, c.0)).collect();
    let seen = samples.iter().filter(|s| s.pos.is_some()).count();
    Ok((seen, fit_rotation(&samples, cfg).map(|f| f.rotated(&cam.table_from_camera))))
}

/// The committed compact model, relative to the repository root.
const DEFAULT_MODEL: &str = "models/logo-compact.onnx";

/// Where the Debian package installs the committed model (Cargo.toml,
/// `[package.metadata.deb]`).
pub const INSTALLED_MODEL: &str = "/usr/share/topspin/models/logo-compact.onnx";

/// The default model's path: `$TOPSPIN_LOGO_MODEL`, else `DEFAULT_MODEL`
/// at the workspace root when it exists (a source checkout), else
/// [`INSTALLED_MODEL`] when it exists (the package), else the relative path.
pub fn default_model() -> PathBuf {
    if let Some(p) = std::env::var_os("TOPSPIN_LOGO_MODEL") {
        return PathBuf::from(p);
    }
    let in_tree = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(DEFAULT_MODEL);
    if in_tree.is_file() {
        in_tree
    } else if Path::new(INSTALLED_MODEL).is_file() {
        PathBuf::from(INSTALLED_MODEL)
    } else {
        PathBuf::from(DEFAULT_MODEL)
    }
}
