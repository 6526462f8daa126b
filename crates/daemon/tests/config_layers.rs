//! The configuration's layers (DESIGN §7): defaults < system file < --config
//! < environment, typos and bad values refused naming the key.

use std::path::{Path, PathBuf};

use topspin_daemon::config::{ConfigError, Core, DaemonConfig, RsiWait};

fn env(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
    pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect()
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn load(system: Option<&Path>, file: Option<&Path>, vars: &[(&str, &str)]) -> Result<DaemonConfig, ConfigError> {
    DaemonConfig::load_layers(system, file, env(vars))
}

#[test]
fn the_example_configuration_equals_the_compiled_defaults() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/topspin.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    // Parsed alone (serde, deny_unknown_fields: every key present, none unknown) ...
    let alone: DaemonConfig = toml::from_str(&text).unwrap();
    assert_eq!(alone, DaemonConfig::default());
    // ... and as a layer.
    assert_eq!(load(None, Some(&path), &[]).unwrap(), DaemonConfig::default());
}

#[test]
fn defaults_when_nothing_is_given() {
    let cfg = load(Some(Path::new("/nonexistent/topspin.toml")), None, &[("HOME", "/root")]).unwrap();
    assert_eq!(cfg, DaemonConfig::default());
    assert_eq!(cfg.network.rsi_bind.to_string(), "127.0.0.1:49152");
    assert_eq!(cfg.threads.rsi_wait, RsiWait::Blocking);
    assert_eq!(cfg.calib.dir(), None);
    assert_eq!(cfg.fixed_latency_ns(), 2_000_000);
}

#[test]
fn later_layers_win_key_by_key() {
    let dir = tempfile::tempdir().unwrap();
    let sys = write(
        dir.path(),
        "system.toml",
        "[network]\nrsi_bind = \"10.0.0.1:49152\"\ntracker_bind = \"10.0.0.1:41000\"\n[tracker]\nnoise_mm = 3.0\n",
    );
    let file =
        write(dir.path(), "mine.toml", "[network]\nrsi_bind = \"10.0.0.2:49152\"\n[threads]\nrsi_core = \"none\"\n");
    let cfg = load(
        Some(&sys),
        Some(&file),
        &[
            ("TOPSPIN_NETWORK__RSI_BIND", "127.0.0.1:6000"),
            ("TOPSPIN_THREADS__RSI_WAIT", "busy_poll"),
            ("TOPSPIN_TRACKER__FIXED_LATENCY_MS", "5"),
            ("TOPSPIN_THREADS__INGEST_CORE", "3"),
            ("TOPSPIN_RSI__SENTYPE", "Lab7"),
            ("TOPSPIN_RECORDING__ENABLED", "true"),
            ("TOPSPIN_UNRELATED", "ignored: not SECTION__KEY"),
            ("PATH", "/usr/bin"),
        ],
    )
    .unwrap();
    assert_eq!(cfg.network.rsi_bind.to_string(), "127.0.0.1:6000"); // environment
    assert_eq!(cfg.network.tracker_bind.to_string(), "10.0.0.1:41000"); // system file
    assert_eq!(cfg.tracker.noise_mm, 3.0); // system file
    assert_eq!(cfg.threads.rsi_core, Core(None)); // --config
    assert_eq!(cfg.threads.estimator_core, Core(Some(1))); // default
    assert_eq!(cfg.threads.ingest_core, Core(Some(3)));
    assert_eq!(cfg.threads.rsi_wait, RsiWait::BusyPoll);
    assert_eq!(cfg.tracker.fixed_latency_ms, 5.0);
    assert_eq!(cfg.rsi.sentype, "Lab7");
    assert!(cfg.recording.enabled);
    // The printed configuration reads back to the same value.
    assert_eq!(DaemonConfig::from_toml(&cfg.to_toml()).unwrap(), cfg);
}

fn err(system: Option<&Path>, file: Option<&Path>, vars: &[(&str, &str)]) -> String {
    let e = load(system, file, vars).unwrap_err().to_string();
    assert!(!e.contains('\n'), "one line: {e}");
    e
}

#[test]
fn typos_are_errors_naming_the_key_and_where() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(dir.path(), "t.toml", "[network]\nrsi_bnd = \"127.0.0.1:1\"\n");
    let e = err(None, Some(&f), &[]);
    assert!(e.contains("t.toml") && e.contains("network.rsi_bnd"), "{e}");
    let f = write(dir.path(), "s.toml", "[netwrk]\n");
    assert!(err(None, Some(&f), &[]).contains("netwrk"));
    let e = err(None, None, &[("TOPSPIN_NETWORK__RSI_BINDD", "127.0.0.1:1")]);
    assert!(e.contains("TOPSPIN_NETWORK__RSI_BINDD") && e.contains("network.rsi_bindd"), "{e}");
    // The system file is checked as strictly.
    let sys = write(dir.path(), "sys.toml", "[tracker]\nnoise = 1.0\n");
    assert!(err(Some(&sys), None, &[]).contains("tracker.noise"));
}

#[test]
fn bad_values_name_the_key() {
    let cases: &[(&str, &str, &str)] = &[
        ("TOPSPIN_NETWORK__RSI_BIND", "x", "network.rsi_bind"),
        ("TOPSPIN_NETWORK__RSI_BIND", "127.0.0.1:0", "network.rsi_bind"),
        ("TOPSPIN_NETWORK__TRACKER_BIND", "127.0.0.1:70000", "network.tracker_bind"),
        ("TOPSPIN_NETWORK__TRACKER_SOURCE", "0.0.0.0", "network.tracker_source"),
        ("TOPSPIN_NETWORK__CONTROLLER_SOURCE", "robot", "network.controller_source"),
        ("TOPSPIN_THREADS__RSI_PRIORITY", "0", "threads.rsi_priority"),
        ("TOPSPIN_THREADS__INGEST_PRIORITY", "100", "threads.ingest_priority"),
        ("TOPSPIN_THREADS__ESTIMATOR_PRIORITY", "-3", "threads.estimator_priority"),
        ("TOPSPIN_THREADS__RSI_CORE", "-1", "threads.rsi_core"),
        ("TOPSPIN_THREADS__RSI_CORE", "4096", "threads.rsi_core"),
        ("TOPSPIN_THREADS__RSI_WAIT", "spin", "threads.rsi_wait"),
        ("TOPSPIN_THREADS__REALTIME", "maybe", "threads.realtime"),
        ("TOPSPIN_TRACKER__NOISE_MM", "0", "tracker.noise_mm"),
        ("TOPSPIN_TRACKER__NOISE_MM", "-2", "tracker.noise_mm"),
        ("TOPSPIN_TRACKER__FIXED_LATENCY_MS", "-1", "tracker.fixed_latency_ms"),
        ("TOPSPIN_RSI__SENTYPE", "a<b", "rsi.sentype"),
        ("TOPSPIN_RSI__CORRECTION", "joint", "rsi.correction"),
        ("TOPSPIN_RSI__CORRECTION", "Axis", "rsi.correction"),
        ("TOPSPIN_TELEMETRY__LOG_INTERVAL_S", "0", "telemetry.log_interval_s"),
        ("TOPSPIN_TELEMETRY__LOG_LEVEL", "loud", "telemetry.log_level"),
    ];
    for (var, value, key) in cases {
        let e = err(None, None, &[(var, value)]);
        assert!(e.starts_with(&format!("{key}:")), "{var}={value}: {e}");
    }
    let e = err(None, None, &[("TOPSPIN_NETWORK__RSI_BIND", "x")]);
    assert_eq!(e, "network.rsi_bind: \"x\" is not an address (IP:PORT)");
    let e = err(None, None, &[("TOPSPIN_RSI__CORRECTION", "joint")]);
    assert_eq!(e, "rsi.correction: \"joint\" is not \"cartesian\" or \"axis\"");
    let axis = load(None, None, &[("TOPSPIN_RSI__CORRECTION", "axis")]).unwrap();
    assert_eq!(axis.rsi.correction(), topspin_core::rsi::Correction::Axis);
}

#[test]
fn unreadable_or_broken_files_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.toml");
    let e = err(None, Some(&missing), &[]);
    assert!(e.starts_with("cannot read") && e.contains("missing.toml"), "{e}");
    let f = write(dir.path(), "broken.toml", "[network]\nrsi_bind = \n");
    let e = err(None, Some(&f), &[]);
    assert!(e.contains("broken.toml") && e.contains("line 2"), "{e}");
    let f = write(dir.path(), "typed.toml", "[tracker]\nnoise_mm = \"loud\"\n");
    let e = err(None, Some(&f), &[]);
    assert!(e.starts_with("tracker.noise_mm:"), "{e}");
}

#[test]
fn the_session_learning_is_set_by_configuration() {
    use topspin_core::estimator::LearnConfig;
    // On by default, with the ball's own drag weighed at the compiled weight.
    let on = DaemonConfig::default().estimator_config();
    assert_eq!(on.learn, LearnConfig { returns: true, ..LearnConfig::default() });
    assert!(on.learn.enabled);
    // The daemon plays its plans: it reads the spin from the returns,
    // unless told its arm does not.
    let no_returns = DaemonConfig::from_toml("[estimator]\nlearn_from_returns = false\n").unwrap();
    assert!(!no_returns.estimator_config().learn.returns);
    // Off: every ball flies with the calibration.
    let off = DaemonConfig::from_toml("[estimator]\nlearn_session = false\n").unwrap();
    assert_eq!(off.estimator_config().learn, LearnConfig::OFF);
    let w = DaemonConfig::from_toml("[estimator]\nball_drag_weight = 0.25\n").unwrap();
    assert_eq!(w.estimator_config().learn.ball_drag_weight, 0.25);
    // Out of range or mistyped: refused, naming the key.
    let e = DaemonConfig::from_toml("[estimator]\nball_drag_weight = 1.5\n").unwrap_err().to_string();
    assert_eq!(e, "estimator.ball_drag_weight: 1.5 is not in [0, 1]");
    let e = err(None, None, &[("TOPSPIN_ESTIMATOR__LEARN_SESSIONS", "false")]);
    assert!(e.contains("estimator.learn_sessions"), "{e}");
    // A configuration without the section (an older recording's) learns.
    assert!(DaemonConfig::from_toml("[tracker]\nnoise_mm = 3.0\n").unwrap().estimator.learn_session);
}
