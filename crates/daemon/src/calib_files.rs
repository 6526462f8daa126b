//! Calibration from a folder: reads a `calib/` directory's files into the
//! core's [`Calibration`] and [`CameraCalib`], which parse text only. A file
//! missing from the folder is the compiled-in default (the repository's
//! `calib/`); errors name the file they come from.

use std::path::{Path, PathBuf};

use topspin_core::calib::{CalibError, Calibration, DEFAULT_PHYSICS, DEFAULT_ROBOT, DEFAULT_STRIKE, DEFAULT_TABLE};
use topspin_core::calib::{CameraCalib, DEFAULT_CAMERA};

/// A calibration that loads from a `calib/` folder.
pub trait CalibDir: Sized {
    /// Loads `dir` (or the compiled defaults with `None`) and validates it.
    fn load(dir: Option<&Path>) -> Result<Self, CalibError>;
}

impl CalibDir for Calibration {
    fn load(dir: Option<&Path>) -> Result<Self, CalibError> {
        check_dir(dir)?;
        let robot = read_file(dir, ROBOT)?;
        from_dir(dir, (&robot.0, &robot.1))
    }
}

impl CalibDir for CameraCalib {
    fn load(dir: Option<&Path>) -> Result<Self, CalibError> {
        check_dir(dir)?;
        let (text, path) = read_or_default(dir, "camera.toml", DEFAULT_CAMERA)?;
        CameraCalib::parse(&text, &path)
    }
}

/// The files of a `calib/` folder that make the [`Calibration`], in the
/// order a recording carries them.
pub const CALIBRATION_FILES: [&str; 4] = ["physics.toml", "table.toml", "strike.toml", "robot.toml"];
/// The compiled-in texts of [`CALIBRATION_FILES`] (the repository's `calib/`).
const CALIBRATION_DEFAULTS: [&str; 4] = [DEFAULT_PHYSICS, DEFAULT_TABLE, DEFAULT_STRIKE, DEFAULT_ROBOT];
// Indices into [`CALIBRATION_FILES`].
const PHYSICS: usize = 0;
const TABLE: usize = 1;
const STRIKE: usize = 2;
const ROBOT: usize = 3;

/// `(name, text)` of each of [`CALIBRATION_FILES`] as [`CalibDir::load`]
/// reads it: from `dir`, or the compiled-in default where `dir` is `None`
/// or lacks the file. What a recording carries.
pub fn calibration_texts(dir: Option<&Path>) -> Result<Vec<(String, String)>, CalibError> {
    (0..CALIBRATION_FILES.len())
        .map(|i| read_file(dir, i).map(|(text, _)| (CALIBRATION_FILES[i].to_owned(), text)))
        .collect()
}

/// The [`Calibration`] from `(name, text)` pairs, as
/// [`calibration_texts`] gives them (a recording's): each of
/// [`CALIBRATION_FILES`] from its text, the compiled-in default where the
/// pairs lack it. Errors name the file as `origin/name`.
pub fn calibration_from_texts(files: &[(String, String)], origin: &str) -> Result<Calibration, CalibError> {
    let file = |i: usize| {
        let name = CALIBRATION_FILES[i];
        let text = files.iter().find(|(n, _)| n == name).map_or(CALIBRATION_DEFAULTS[i], |(_, t)| t.as_str());
        (text, PathBuf::from(format!("{origin}/{name}")))
    };
    let (physics, table, strike, robot) = (file(PHYSICS), file(TABLE), file(STRIKE), file(ROBOT));
    Calibration::from_texts((physics.0, &physics.1), (table.0, &table.1), (strike.0, &strike.1), (robot.0, &robot.1))
}

/// Loads `dir` as [`CalibDir::load`] does, with `robot_text` in place of
/// its `robot.toml` (errors name `dir/robot.toml`): how a new `robot.toml`
/// is checked against the rest of the cell before it replaces the old one.
pub fn load_with_robot(dir: Option<&Path>, robot_text: &str) -> Result<Calibration, CalibError> {
    let name = CALIBRATION_FILES[ROBOT];
    let robot_path = dir.map_or_else(|| PathBuf::from(format!("<default>/{name}")), |d| d.join(name));
    from_dir(dir, (robot_text, &robot_path))
}

fn from_dir(dir: Option<&Path>, robot: (&str, &Path)) -> Result<Calibration, CalibError> {
    let physics = read_file(dir, PHYSICS)?;
    let table = read_file(dir, TABLE)?;
    let strike = read_file(dir, STRIKE)?;
    Calibration::from_texts((&physics.0, &physics.1), (&table.0, &table.1), (&strike.0, &strike.1), robot)
}

fn check_dir(dir: Option<&Path>) -> Result<(), CalibError> {
    match dir {
        Some(d) if !d.is_dir() => Err(CalibError::Read {
            path: d.to_owned(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "not a directory"),
        }),
        _ => Ok(()),
    }
}

/// [`read_or_default`] for file `i` of [`CALIBRATION_FILES`].
fn read_file(dir: Option<&Path>, i: usize) -> Result<(String, PathBuf), CalibError> {
    read_or_default(dir, CALIBRATION_FILES[i], CALIBRATION_DEFAULTS[i])
}

/// `dir/name`'s text and path, or the compiled default's with the path
/// `<default>/name` where `dir` is `None` or holds no such file.
fn read_or_default(dir: Option<&Path>, name: &str, default: &'static str) -> Result<(String, PathBuf), CalibError> {
    if let Some(path) = dir.map(|d| d.join(name))
        && path.exists()
    {
        let text = std::fs::read_to_string(&path).map_err(|source| CalibError::Read { path: path.clone(), source })?;
        return Ok((text, path));
    }
    Ok((default.to_owned(), PathBuf::from(format!("<default>/{name}"))))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_value_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let write = |text: String| std::fs::write(dir.path().join("strike.toml"), text).unwrap();
        write(DEFAULT_STRIKE.replace("hit_plane_x = 1.60", "hit_plane_x = -3.0"));
        let e = Calibration::load(Some(dir.path())).unwrap_err().to_string();
        assert!(e.contains("strike.hit_plane_x"), "{e}");
        write(DEFAULT_STRIKE.replace("hit_plane_x = 1.60", "hit_plane = 1.6"));
        let e = Calibration::load(Some(dir.path())).unwrap_err().to_string();
        assert!(e.contains("hit_plane"), "{e}");
        write(DEFAULT_STRIKE.replace("window_y = [-0.70, 0.70]", "window_y = [-0.90, 0.70]"));
        let e = Calibration::load(Some(dir.path())).unwrap_err().to_string();
        assert!(e.contains("strike.window_y") && e.contains("workspace"), "{e}");
    }

    #[test]
    fn a_folder_without_files_is_the_default_cell_and_a_file_is_no_folder() {
        let dir = tempfile::tempdir().unwrap();
        let c = Calibration::load(Some(dir.path())).unwrap();
        assert_eq!(c.strike.hit_plane_x, Calibration::default_cell().strike.hit_plane_x);
        assert_eq!(CameraCalib::load(Some(dir.path())).unwrap().f_px, CameraCalib::default_camera().f_px);
        let file = dir.path().join("robot.toml");
        std::fs::write(&file, DEFAULT_ROBOT).unwrap();
        for e in [Calibration::load(Some(&file)).map(|_| ()), CameraCalib::load(Some(&file)).map(|_| ())] {
            assert!(e.unwrap_err().to_string().contains("not a directory"));
        }
        let e = load_with_robot(Some(dir.path()), "[joints]\n").map(|_| ()).unwrap_err().to_string();
        assert!(e.contains("robot.toml"), "{e}");
    }

    #[test]
    fn recorded_texts_give_the_folders_calibration_and_name_their_file() {
        let dir = tempfile::tempdir().unwrap();
        let strike = DEFAULT_STRIKE.replace("hit_plane_x = 1.60", "hit_plane_x = 1.55");
        std::fs::write(dir.path().join("strike.toml"), &strike).unwrap();
        let texts = calibration_texts(Some(dir.path())).unwrap();
        let names: Vec<&str> = texts.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, CALIBRATION_FILES);
        assert_eq!(texts[2].1, strike);
        assert_eq!(texts[0].1, DEFAULT_PHYSICS);
        let from_texts = calibration_from_texts(&texts, "<recorded>").unwrap();
        assert_eq!(from_texts, Calibration::load(Some(dir.path())).unwrap());
        // A file the pairs lack is the default; a bad one is named.
        assert_eq!(calibration_from_texts(&texts[..2], "<recorded>").unwrap(), Calibration::default_cell());
        let bad = vec![("strike.toml".to_owned(), DEFAULT_STRIKE.replace("hit_plane_x = 1.60", "hit_plane_x = -3.0"))];
        let e = calibration_from_texts(&bad, "<recorded>").unwrap_err().to_string();
        assert!(e.contains("<recorded>/strike.toml") && e.contains("strike.hit_plane_x"), "{e}");
    }
}
