//! The committed logo CNN on ONNX Runtime, loaded at run time from the
//! shared library of the PyPI wheel `onnxruntime` (README, Setup):
//! `ORT_DYLIB_PATH`, or else the wheel that `python3` imports.
//!
//! The library is an optional system part: where it is absent the test says
//! so on stderr and passes, unless `TOPSPIN_REQUIRE_ONNXRUNTIME=1` (set by
//! `.ci/run`, which installs the wheel) turns the skip into a failure.

mod common;

use std::path::PathBuf;

fn onnxruntime_library() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("ORT_DYLIB_PATH").filter(|p| !p.is_empty()) {
        return Some(PathBuf::from(p));
    }
    let out = std::process::Command::new("python3")
        .args(["-c", "import onnxruntime, os; print(os.path.dirname(onnxruntime.__file__))"])
        .output()
        .ok()?;
    let capi = PathBuf::from(String::from_utf8(out.stdout).ok()?.trim()).join("capi");
    std::fs::read_dir(&capi)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("libonnxruntime.so.")))
}

#[test]
fn the_committed_model_runs_on_onnxruntime() {
    let Some(lib) = onnxruntime_library() else {
        let note = "no ONNX Runtime library: `python3 -m pip install onnxruntime==1.31.1` (README, Setup) or set ORT_DYLIB_PATH";
        if std::env::var_os("TOPSPIN_REQUIRE_ONNXRUNTIME").is_some_and(|v| v == "1") {
            panic!("{note} (TOPSPIN_REQUIRE_ONNXRUNTIME=1)");
        }
        // Straight to stderr, past the test harness's capture: a skip
        // must be seen, not only when the test fails.
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), "SKIPPED the_committed_model_runs_on_onnxruntime: {note}");
        return;
    };
    // SAFETY: this test binary has one test; nothing else runs yet.
    #[allow(unsafe_code)]
    unsafe {
        std::env::set_var("ORT_DYLIB_PATH", &lib)
    };
    common::logo_cnn::check(topspin_cnn::Backend::OnnxRuntime);
}
