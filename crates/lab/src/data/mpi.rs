//! Loader for the MPI launcher set (`shared/data/mpi-launcher/`, BSD-3,
//! read in place): one [`RealTrajectory`] per `SET/NNN.csv`, with the five
//! launcher settings from `index.csv`.
//!
//! Each CSV has the header `t,x,y,z,vx,vy,vz` (s, m in the *lab* frame, m/s).
//! Only `t,x,y,z` are kept: the tracker's own velocity column is zero on
//! every sample where it had no estimate, so it is not a measurement we can
//! use. Every malformed row is a typed error naming the file and line; the
//! loader never panics on its input.

use std::path::{Path, PathBuf};

use topspin_core::physics::Vec3;

/// The four subsets, in the order they are reported.
pub const SETS: [&str; 4] = ["backspin", "topspin", "no_spin", "robot_no_spin"];

/// Name of the per-set index file.
pub(crate) const INDEX_FILE: &str = "index.csv";

/// Environment variable that points at the `mpi-launcher` folder.
pub const DATA_ENV: &str = "TOPSPIN_MPI_DATA";

/// Where the set lives relative to the repository root in CI (the repo is
/// cloned with `shared/` beside it).
pub(crate) const DATA_REL_PATH: &str = "../shared/data/mpi-launcher";

/// One recorded launcher shot, positions in the lab frame.
#[derive(Clone, Debug, PartialEq)]
pub struct RealTrajectory {
    /// The subset (`backspin`, `topspin`, `no_spin`, `robot_no_spin`).
    pub set: String,
    /// The file number within the subset (`NNN.csv`).
    pub index: usize,
    /// The launcher's five settings (`launch_p0..4`), uncalibrated.
    pub launcher: [f64; 5],
    /// (t in s from the first sample, position in m, lab frame), strictly
    /// increasing in t.
    pub samples: Vec<(f64, Vec3)>,
}

impl RealTrajectory {
    /// A short name, `set/NNN`.
    pub fn name(&self) -> String {
        format!("{}/{:03}", self.set, self.index)
    }
}

/// Why the set (or one file of it) cannot be loaded.
#[derive(Debug, thiserror::Error)]
pub enum MpiError {
    /// A file or folder could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The CSV layer failed (bad quoting, ragged row, invalid UTF-8).
    #[error("{path}: {source}")]
    Csv {
        /// The file.
        path: PathBuf,
        /// The CSV reader's error.
        source: csv::Error,
    },
    /// A required column is not in the header.
    #[error("{path}: no column `{column}` in the header")]
    MissingColumn {
        /// The file.
        path: PathBuf,
        /// The column's name.
        column: &'static str,
    },
    /// A field is missing, not a number, or not finite.
    #[error("{path}:{line}: `{column}` = {text:?} is not a finite number")]
    BadValue {
        /// The file.
        path: PathBuf,
        /// The line in the file.
        line: u64,
        /// The column's name.
        column: &'static str,
        /// The field as read.
        text: String,
    },
    /// Time does not increase strictly from one row to the next.
    #[error("{path}:{line}: time {t} does not increase (previous {previous})")]
    TimeNotIncreasing {
        /// The file.
        path: PathBuf,
        /// The line in the file.
        line: u64,
        /// The row's time, s.
        t: f64,
        /// The previous row's time, s.
        previous: f64,
    },
    /// The index names a set or file number that makes no sense.
    #[error("{path}:{line}: bad index entry: {reason}")]
    BadIndex {
        /// The index file.
        path: PathBuf,
        /// The line in the file.
        line: u64,
        /// What is wrong with the entry.
        reason: &'static str,
    },
    /// A trajectory file holds fewer samples than any use of it needs.
    #[error("{path}: only {samples} samples")]
    TooFewSamples {
        /// The file.
        path: PathBuf,
        /// Samples in the file.
        samples: usize,
    },
}

/// Finds the data folder: `$TOPSPIN_MPI_DATA` if set, else
/// `<repo_root>/../shared/data/mpi-launcher`. `None` when neither holds an
/// `index.csv` (tests then skip with a note).
pub fn locate(repo_root: &Path) -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os(DATA_ENV) {
        let dir = PathBuf::from(dir);
        return dir.join(INDEX_FILE).is_file().then_some(dir);
    }
    let dir = repo_root.join(DATA_REL_PATH);
    dir.join(INDEX_FILE).is_file().then_some(dir)
}

/// One row of `index.csv`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct IndexEntry {
    pub set: String,
    pub index: usize,
    pub launcher: [f64; 5],
    /// The sample count the index claims (checked against the file).
    pub samples: usize,
}

fn csv_err(path: &Path) -> impl Fn(csv::Error) -> MpiError + '_ {
    move |source| MpiError::Csv { path: path.to_owned(), source }
}

fn column(headers: &csv::StringRecord, name: &'static str, path: &Path) -> Result<usize, MpiError> {
    headers
        .iter()
        .position(|h| h.trim() == name)
        .ok_or_else(|| MpiError::MissingColumn { path: path.to_owned(), column: name })
}

fn number(rec: &csv::StringRecord, col: usize, name: &'static str, path: &Path) -> Result<f64, MpiError> {
    let text = rec.get(col).unwrap_or("");
    let line = rec.position().map_or(0, |p| p.line());
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(MpiError::BadValue { path: path.to_owned(), line, column: name, text: text.to_owned() }),
    }
}

fn reader(path: &Path) -> Result<csv::Reader<std::fs::File>, MpiError> {
    let file = std::fs::File::open(path).map_err(|source| MpiError::Io { path: path.to_owned(), source })?;
    Ok(csv::ReaderBuilder::new().flexible(false).from_reader(file))
}

/// Reads `index.csv`.
pub(crate) fn read_index(path: &Path) -> Result<Vec<IndexEntry>, MpiError> {
    let mut rdr = reader(path)?;
    let headers = rdr.headers().map_err(csv_err(path))?.clone();
    let c_set = column(&headers, "set", path)?;
    let c_index = column(&headers, "index", path)?;
    let c_samples = column(&headers, "samples", path)?;
    const P: [&str; 5] = ["launch_p0", "launch_p1", "launch_p2", "launch_p3", "launch_p4"];
    let mut c_p = [0usize; 5];
    for (c, name) in c_p.iter_mut().zip(P) {
        *c = column(&headers, name, path)?;
    }
    let mut out = Vec::new();
    for rec in rdr.records() {
        let rec = rec.map_err(csv_err(path))?;
        let line = rec.position().map_or(0, |p| p.line());
        let bad = |reason| MpiError::BadIndex { path: path.to_owned(), line, reason };
        let set = rec.get(c_set).unwrap_or("").trim().to_owned();
        if set.is_empty() || set.contains(['/', '\\', '.']) {
            return Err(bad("set name is empty or not a plain folder name"));
        }
        let index = rec
            .get(c_index)
            .and_then(|s| s.trim().parse::<usize>().ok())
            .ok_or_else(|| bad("index is not a non-negative integer"))?;
        let samples = rec
            .get(c_samples)
            .and_then(|s| s.trim().parse::<usize>().ok())
            .ok_or_else(|| bad("samples is not a non-negative integer"))?;
        let mut launcher = [0.0; 5];
        for ((l, &c), name) in launcher.iter_mut().zip(&c_p).zip(P) {
            *l = number(&rec, c, name, path)?;
        }
        out.push(IndexEntry { set, index, launcher, samples });
    }
    Ok(out)
}

/// Reads one trajectory file (`t,x,y,z,...`), lab frame.
pub(crate) fn read_samples(path: &Path) -> Result<Vec<(f64, Vec3)>, MpiError> {
    let mut rdr = reader(path)?;
    let headers = rdr.headers().map_err(csv_err(path))?.clone();
    let cols = [
        column(&headers, "t", path)?,
        column(&headers, "x", path)?,
        column(&headers, "y", path)?,
        column(&headers, "z", path)?,
    ];
    let mut out: Vec<(f64, Vec3)> = Vec::new();
    for rec in rdr.records() {
        let rec = rec.map_err(csv_err(path))?;
        let t = number(&rec, cols[0], "t", path)?;
        let x = number(&rec, cols[1], "x", path)?;
        let y = number(&rec, cols[2], "y", path)?;
        let z = number(&rec, cols[3], "z", path)?;
        if let Some(&(previous, _)) = out.last()
            && t <= previous
        {
            return Err(MpiError::TimeNotIncreasing {
                path: path.to_owned(),
                line: rec.position().map_or(0, |p| p.line()),
                t,
                previous,
            });
        }
        out.push((t, Vec3::new(x, y, z)));
    }
    Ok(out)
}

/// The fewest samples a file must hold to be loaded at all.
pub(crate) const MIN_FILE_SAMPLES: usize = 8;

/// Loads every trajectory listed in `dir/index.csv`, in index order.
pub fn load(dir: &Path) -> Result<Vec<RealTrajectory>, MpiError> {
    let index = read_index(&dir.join(INDEX_FILE))?;
    index
        .into_iter()
        .map(|e| {
            let path = dir.join(&e.set).join(format!("{:03}.csv", e.index));
            let samples = read_samples(&path)?;
            if samples.len() < MIN_FILE_SAMPLES {
                return Err(MpiError::TooFewSamples { path, samples: samples.len() });
            }
            Ok(RealTrajectory { set: e.set, index: e.index, launcher: e.launcher, samples })
        })
        .collect()
}

/// Sampling and coverage statistics of a group of trajectories (what
/// `docs/real-data.md` reports).
#[derive(Clone, Debug, PartialEq)]
pub struct SamplingStats {
    /// Trajectories in the group.
    pub trajectories: usize,
    /// Samples over all of them.
    pub samples: usize,
    /// Median interval between consecutive samples, s.
    pub median_dt: f64,
    /// Largest interval, s.
    pub max_dt: f64,
    /// Intervals longer than 1.5 × the median (dropped frames).
    pub gaps: usize,
    /// Shortest and longest recording, s.
    pub duration: (f64, f64),
    /// Residual RMS (per axis, m) of a local quadratic through 7 samples,
    /// away from bounces: the tracker's noise plus the model error of a
    /// quadratic over ~35 ms (negligible in flight).
    pub noise_rms: Vec3,
}

/// Median of `v` (sorts it); NaN when empty.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}

/// Statistics over `trajs` (any subset). `skip_near_z` leaves out windows
/// that reach below that lab height (bounces) from the noise estimate.
pub fn sampling_stats(trajs: &[&RealTrajectory], skip_near_z: f64) -> SamplingStats {
    const HALF: usize = 3;
    let mut dts = Vec::new();
    let mut durations = Vec::new();
    let mut samples = 0;
    let mut sq = Vec3::zeros();
    let mut n_res = 0usize;
    for tr in trajs {
        let s = &tr.samples;
        samples += s.len();
        if let (Some(a), Some(b)) = (s.first(), s.last()) {
            durations.push(b.0 - a.0);
        }
        dts.extend(s.windows(2).map(|w| w[1].0 - w[0].0));
        for i in HALF..s.len().saturating_sub(HALF) {
            let win = &s[i - HALF..=i + HALF];
            if win.iter().any(|(_, p)| p.z < skip_near_z) {
                continue;
            }
            let t0 = s[i].0;
            for axis in 0..3 {
                let pts: Vec<(f64, f64)> = win.iter().map(|(t, p)| (t - t0, p[axis])).collect();
                if let Some(c) = super::polyfit::polyfit::<3>(&pts) {
                    let r = s[i].1[axis] - c[0];
                    sq[axis] += r * r;
                }
            }
            n_res += 1;
        }
    }
    let max_dt = dts.iter().copied().fold(0.0, f64::max);
    let median_dt = median(&mut dts.clone());
    let gaps = dts.iter().filter(|&&d| d > 1.5 * median_dt).count();
    // The centre sample's residual of a 7-point quadratic has variance
    // σ²(1 − h_ii); h_ii = 0.333 for 7 equally spaced points, degree 2.
    let noise_rms =
        if n_res > 0 { (sq / (n_res as f64 * (1.0 - 1.0 / 3.0))).map(f64::sqrt) } else { Vec3::repeat(f64::NAN) };
    SamplingStats {
        trajectories: trajs.len(),
        samples,
        median_dt,
        max_dt,
        gaps,
        duration: (
            durations.iter().copied().fold(f64::INFINITY, f64::min),
            durations.iter().copied().fold(0.0, f64::max),
        ),
        noise_rms,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn tmp(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("topspin-mpi-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn reads_good_rows_and_ignores_extra_columns() {
        let d = tmp("good");
        let p = write(&d, "a.csv", "t,x,y,z,vx,vy,vz\n0.0,1,2,3,0,0,0\n0.01,1.1,2,3,,,\n");
        let s = read_samples(&p).unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(s[1].1, Vec3::new(1.1, 2.0, 3.0));
    }

    #[test]
    fn bad_rows_are_typed_errors() {
        let d = tmp("bad");
        let p = write(&d, "nan.csv", "t,x,y,z\n0,1,2,3\n0.1,nan,2,3\n");
        assert!(matches!(read_samples(&p), Err(MpiError::BadValue { column: "x", line: 3, .. })));
        let p = write(&d, "text.csv", "t,x,y,z\n0,1,2,abc\n");
        assert!(matches!(read_samples(&p), Err(MpiError::BadValue { column: "z", .. })));
        let p = write(&d, "ragged.csv", "t,x,y,z\n0,1,2\n");
        assert!(matches!(read_samples(&p), Err(MpiError::Csv { .. })));
        let p = write(&d, "back.csv", "t,x,y,z\n0.1,1,2,3\n0.1,1,2,3\n");
        assert!(matches!(read_samples(&p), Err(MpiError::TimeNotIncreasing { .. })));
        let p = write(&d, "nocol.csv", "t,x,z\n0,1,2\n");
        assert!(matches!(read_samples(&p), Err(MpiError::MissingColumn { column: "y", .. })));
        assert!(matches!(read_samples(&d.join("absent.csv")), Err(MpiError::Io { .. })));
        let p = write(
            &d,
            "index.csv",
            "set,index,launch_p0,launch_p1,launch_p2,launch_p3,launch_p4,samples\n../x,0,1,1,1,1,1,5\n",
        );
        assert!(matches!(read_index(&p), Err(MpiError::BadIndex { .. })));
    }

    #[test]
    fn median_of_even_and_odd() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&mut []).is_nan());
    }
}
