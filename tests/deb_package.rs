//! The Debian package (Cargo.toml `[package.metadata.deb]`, README
//! "Installing on the robot PC").
//!
//! Without cargo-deb (CI does not install it): the metadata parses, every
//! asset's source exists, the conffile is `deploy/topspin.toml`, the
//! calibration and RSI folders are shipped whole, the maintainer scripts
//! pass `sh -n` and carry the `#DEBHELPER#` token, the sysusers line is
//! well formed, the unit runs as that user with the state directory and
//! the real-time rights, `systemd-analyze verify` accepts it (where
//! systemd-analyze exists), and systemd-sysusers / systemd-tmpfiles make
//! the user and the state directory in a scratch root (where they exist
//! and this runs as root).
//!
//! With cargo-deb (`cargo install cargo-deb --locked`): the package is
//! built from this build's binary (`cargo deb --no-build`), its paths,
//! conffiles and maintainer scripts are checked, it is unpacked into a
//! scratch root, and the unpacked binary (no debug info) runs `--version`,
//! `doctor` on the unpacked configuration and a command on the unpacked
//! calibration. Where cargo-deb is absent that test says so on stderr and
//! passes, unless `TOPSPIN_REQUIRE_CARGO_DEB=1` turns the skip into a
//! failure.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A skip must be seen: straight to stderr, past the harness's capture.
fn skipped(test: &str, why: &str) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "SKIPPED {test}: {why}");
}

fn deb_metadata() -> toml::Table {
    let text = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    let manifest: toml::Table = text.parse().unwrap();
    manifest["package"]["metadata"]["deb"].as_table().expect("[package.metadata.deb]").clone()
}

/// `(source, dest, mode)` of every asset, in order.
fn assets(deb: &toml::Table) -> Vec<(String, String, String)> {
    deb["assets"]
        .as_array()
        .expect("assets")
        .iter()
        .map(|a| {
            let a = a.as_array().expect("an asset is [source, dest, mode]");
            assert_eq!(a.len(), 3, "{a:?}");
            let s = |i: usize| a[i].as_str().unwrap().to_owned();
            (s(0), s(1), s(2))
        })
        .collect()
}

/// Where an asset lands: `dest`, or `dest` + the source's file name when
/// `dest` is a folder (ends in `/`).
fn installed_path(source: &str, dest: &str) -> String {
    if dest.ends_with('/') {
        format!("{dest}{}", Path::new(source).file_name().unwrap().to_str().unwrap())
    } else {
        dest.to_owned()
    }
}

fn files_in(dir: &str) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(root().join(dir))
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_type().unwrap().is_file())
        .map(|e| format!("{dir}/{}", e.file_name().to_str().unwrap()))
        .collect();
    v.sort();
    v
}

fn unit_dir(deb: &toml::Table) -> PathBuf {
    let units = deb["systemd-units"].as_table().expect("[package.metadata.deb.systemd-units]");
    root().join(units["unit-scripts"].as_str().unwrap())
}

fn scripts_dir(deb: &toml::Table) -> PathBuf {
    root().join(deb["maintainer-scripts"].as_str().expect("maintainer-scripts"))
}

/// `Key=value` lines of a unit, in order (comments and sections dropped).
fn unit_keys(text: &str) -> Vec<(String, String)> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with(['#', ';', '[']))
        .map(|l| {
            let (k, v) = l.split_once('=').unwrap_or_else(|| panic!("not Key=value: {l}"));
            (k.to_owned(), v.to_owned())
        })
        .collect()
}

fn unit_value<'a>(keys: &'a [(String, String)], key: &str) -> Vec<&'a str> {
    keys.iter().filter(|(k, _)| k == key).map(|(_, v)| v.as_str()).collect()
}

fn have(tool: &str) -> bool {
    Command::new(tool).arg("--version").output().is_ok_and(|o| o.status.success())
}

fn is_root() -> bool {
    Command::new("id").arg("-u").output().is_ok_and(|o| o.stdout.trim_ascii() == b"0")
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

#[test]
fn every_asset_exists_and_the_folders_are_shipped_whole() {
    let deb = deb_metadata();
    let assets = assets(&deb);
    for (src, dest, mode) in &assets {
        assert!(!dest.starts_with('/'), "cargo-deb dests are relative: {dest}");
        assert!(mode == "644" || mode == "755", "{src}: mode {mode}");
        if src.starts_with("target/release/") {
            continue; // cargo-deb maps it to the real target dir
        }
        assert!(root().join(src).is_file(), "asset source {src} is missing");
    }
    let lands: Vec<(String, String)> = assets.iter().map(|(s, d, _)| (s.clone(), installed_path(s, d))).collect();
    let at = |src: &str| lands.iter().find(|(s, _)| s == src).map(|(_, d)| d.as_str());

    assert_eq!(at("target/release/topspin"), Some("usr/bin/topspin"));
    let bin_mode = &assets.iter().find(|a| a.0 == "target/release/topspin").unwrap().2;
    assert_eq!(bin_mode, "755");
    // The conffile: the documented defaults, under /etc.
    assert_eq!(at("deploy/topspin.toml"), Some("etc/topspin/topspin.toml"));
    let conf: Vec<&str> = deb["conf-files"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    assert_eq!(conf, ["/etc/topspin/topspin.toml"]);
    for f in files_in("calib") {
        let name = Path::new(&f).file_name().unwrap().to_str().unwrap().to_owned();
        assert_eq!(at(&f), Some(format!("usr/share/topspin/calib/{name}").as_str()), "{f} is not shipped");
    }
    for f in files_in("rsi") {
        let name = Path::new(&f).file_name().unwrap().to_str().unwrap().to_owned();
        assert_eq!(at(&f), Some(format!("usr/share/topspin/rsi/{name}").as_str()), "{f} is not shipped");
    }
    // The logo model where `default_model()` looks for it once installed.
    assert_eq!(at("models/logo-compact.onnx").map(|d| format!("/{d}")), Some(topspin_cnn::INSTALLED_MODEL.to_owned()));
    assert_eq!(at("README.md"), Some("usr/share/doc/topspin/README.md"));
    assert_eq!(at("deploy/README.md"), Some("usr/share/doc/topspin/deploy.md"));
    // The unit's Documentation= names the packaged README.
    let unit = std::fs::read_to_string(unit_dir(&deb).join("topspin.service")).unwrap();
    assert_eq!(unit_value(&unit_keys(&unit), "Documentation"), ["file:///usr/share/doc/topspin/README.md"]);
    // Depends: the shared libraries, and systemd-sysusers for the postinst.
    let depends = deb["depends"].as_str().unwrap();
    assert!(depends.contains("$auto") && depends.contains("systemd"), "{depends}");
}

#[test]
fn the_unit_runs_as_the_sysusers_user_with_the_state_directory() {
    let deb = deb_metadata();
    let dir = unit_dir(&deb);
    // The sysusers entry: one `u` line, name, auto id, a quoted GECOS, the
    // state directory as home, no login shell.
    let sysusers = std::fs::read_to_string(dir.join("topspin.sysusers")).unwrap();
    let lines: Vec<&str> = sysusers.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')).collect();
    assert_eq!(lines.len(), 1, "{lines:?}");
    let (head, rest) = lines[0].split_once(" \"").expect("a quoted GECOS");
    let (gecos, tail) = rest.split_once("\" ").expect("a closed GECOS");
    assert_eq!(head.split_whitespace().collect::<Vec<_>>(), ["u", "topspin", "-"]);
    assert!(!gecos.is_empty() && !gecos.contains([':', '"']), "{gecos}");
    assert_eq!(tail.split_whitespace().collect::<Vec<_>>(), ["/var/lib/topspin", "/usr/sbin/nologin"]);

    // The state directory of the tmpfiles line is the recording folder of
    // the packaged configuration.
    let tmpfiles = std::fs::read_to_string(dir.join("topspin.tmpfile")).unwrap();
    let lines: Vec<&str> = tmpfiles.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')).collect();
    assert_eq!(lines, ["d /var/lib/topspin 0750 topspin topspin -"]);
    let cfg = topspin_daemon::config::DaemonConfig::from_toml(
        &std::fs::read_to_string(root().join("deploy/topspin.toml")).unwrap(),
    )
    .unwrap();
    assert_eq!(cfg.recording.dir, Path::new("/var/lib/topspin"));

    let unit = std::fs::read_to_string(dir.join("topspin.service")).unwrap();
    let keys = unit_keys(&unit);
    assert_eq!(unit_value(&keys, "ExecStart"), ["/usr/bin/topspin run --config /etc/topspin/topspin.toml"]);
    assert_eq!(unit_value(&keys, "User"), ["topspin"]);
    assert_eq!(unit_value(&keys, "Group"), ["topspin"]);
    assert_eq!(unit_value(&keys, "StateDirectory"), ["topspin"]);
    assert_eq!(unit_value(&keys, "ConfigurationDirectory"), ["topspin"]);
    // What deploy/README.md says real-time needs (SCHED_FIFO, mlockall).
    assert_eq!(unit_value(&keys, "AmbientCapabilities"), ["CAP_SYS_NICE CAP_IPC_LOCK"]);
    assert_eq!(unit_value(&keys, "CapabilityBoundingSet"), ["CAP_SYS_NICE CAP_IPC_LOCK"]);
    assert_eq!(unit_value(&keys, "LimitMEMLOCK"), ["infinity"]);
    assert_eq!(unit_value(&keys, "LimitRTPRIO"), ["99"]);
    assert_eq!(unit_value(&keys, "ProtectSystem"), ["strict"]);
    assert_eq!(unit_value(&keys, "Type"), ["notify"]);
}

#[test]
fn maintainer_scripts_parse_and_carry_the_debhelper_token() {
    let deb = deb_metadata();
    let dir = scripts_dir(&deb);
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_str().unwrap().to_owned();
        assert!(
            ["preinst", "postinst", "prerm", "postrm"].contains(&name.as_str()),
            "unexpected file {name} in {dir:?}"
        );
        let body = std::fs::read_to_string(&p).unwrap();
        assert!(body.starts_with("#!/bin/sh\n"), "{name}: #!/bin/sh");
        assert!(body.contains("\nset -e\n"), "{name}: set -e");
        // cargo-deb replaces every occurrence, a comment's too.
        assert_eq!(body.matches("#DEBHELPER#").count(), 1, "{name}: the token once");
        assert!(
            body.contains("\n#DEBHELPER#\n"),
            "{name}: cargo-deb's systemd snippets go at #DEBHELPER#, on a line of its own"
        );
        use std::os::unix::fs::PermissionsExt as _;
        assert_eq!(std::fs::metadata(&p).unwrap().permissions().mode() & 0o111, 0o111, "{name} is not executable");
        let o = Command::new("sh").arg("-n").arg(&p).output().unwrap();
        assert!(o.status.success(), "sh -n {name}: {}", text(&o));
        n += 1;
    }
    assert!(n > 0, "no maintainer scripts in {dir:?}");
}

/// A copy of `unit` with `ExecStart`'s program replaced by `bin` in
/// `dir`: `systemd-analyze verify` checks that the program exists.
fn unit_with_program(unit: &str, bin: &Path, dir: &Path) -> PathBuf {
    assert!(unit.contains("ExecStart=/usr/bin/topspin "));
    let p = dir.join("topspin.service");
    std::fs::write(&p, unit.replace("ExecStart=/usr/bin/topspin ", &format!("ExecStart={} ", bin.display()))).unwrap();
    p
}

/// `systemd-analyze verify` exits 0 on a mere unknown key but prints it:
/// any line naming the unit counts.
fn assert_verifies(unit: &Path) {
    let o = Command::new("systemd-analyze").args(["verify", "--man=no"]).arg(unit).output().unwrap();
    let out = text(&o);
    assert!(o.status.success(), "systemd-analyze verify: {out}");
    assert!(!out.contains("topspin.service"), "systemd-analyze verify: {out}");
}

#[test]
fn systemd_analyze_verifies_the_unit() {
    if !have("systemd-analyze") {
        return skipped("systemd_analyze_verifies_the_unit", "no systemd-analyze on this machine");
    }
    let deb = deb_metadata();
    let unit = std::fs::read_to_string(unit_dir(&deb).join("topspin.service")).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    assert_verifies(&unit_with_program(&unit, Path::new(env!("CARGO_BIN_EXE_topspin")), tmp.path()));
    // And it does catch a mistake.
    let bad = tmp.path().join("bad");
    std::fs::create_dir(&bad).unwrap();
    let p =
        unit_with_program(&unit.replace("User=topspin", "Usr=topspin"), Path::new(env!("CARGO_BIN_EXE_topspin")), &bad);
    let o = Command::new("systemd-analyze").args(["verify", "--man=no"]).arg(&p).output().unwrap();
    assert!(text(&o).contains("Usr"), "{}", text(&o));
}

/// systemd-sysusers and systemd-tmpfiles against a scratch root, as the
/// postinst runs them against `/`.
fn make_user_and_state_dir(scratch: &Path, sysusers: &Path, tmpfiles: &Path) {
    for (src, dir) in [(sysusers, "usr/lib/sysusers.d"), (tmpfiles, "usr/lib/tmpfiles.d")] {
        let d = scratch.join(dir);
        std::fs::create_dir_all(&d).unwrap();
        if src != d.join("topspin.conf") {
            std::fs::copy(src, d.join("topspin.conf")).unwrap();
        }
    }
    std::fs::create_dir_all(scratch.join("etc")).unwrap();
    let root_arg = format!("--root={}", scratch.display());
    let o = Command::new("systemd-sysusers").arg(&root_arg).arg("topspin.conf").output().unwrap();
    assert!(o.status.success(), "systemd-sysusers: {}", text(&o));
    let passwd = std::fs::read_to_string(scratch.join("etc/passwd")).unwrap();
    let line = passwd.lines().find(|l| l.starts_with("topspin:")).unwrap_or_else(|| panic!("no topspin in {passwd}"));
    let f: Vec<&str> = line.split(':').collect();
    assert_eq!((f[5], f[6]), ("/var/lib/topspin", "/usr/sbin/nologin"), "{line}");
    let uid: u32 = f[2].parse().unwrap();
    assert!((1..1000).contains(&uid), "a system uid: {line}");
    let group = std::fs::read_to_string(scratch.join("etc/group")).unwrap();
    assert!(group.lines().any(|l| l.starts_with(&format!("topspin:x:{}:", f[3]))), "{group}");

    let o = Command::new("systemd-tmpfiles").arg(&root_arg).args(["--create", "topspin.conf"]).output().unwrap();
    assert!(o.status.success(), "systemd-tmpfiles: {}", text(&o));
    use std::os::unix::fs::{MetadataExt as _, PermissionsExt as _};
    let m = std::fs::metadata(scratch.join("var/lib/topspin")).unwrap();
    assert!(m.is_dir());
    assert_eq!(m.permissions().mode() & 0o7777, 0o750);
    assert_eq!((m.uid(), m.gid().to_string()), (uid, f[3].to_owned()));
}

#[test]
fn sysusers_and_tmpfiles_make_the_user_and_state_dir_in_a_scratch_root() {
    let name = "sysusers_and_tmpfiles_make_the_user_and_state_dir_in_a_scratch_root";
    if !(have("systemd-sysusers") && have("systemd-tmpfiles")) {
        return skipped(name, "no systemd-sysusers / systemd-tmpfiles on this machine");
    }
    if !is_root() {
        return skipped(name, "not root (systemd-tmpfiles must chown the state directory)");
    }
    let dir = unit_dir(&deb_metadata());
    let tmp = tempfile::tempdir().unwrap();
    make_user_and_state_dir(tmp.path(), &dir.join("topspin.sysusers"), &dir.join("topspin.tmpfile"));
}

/// The section names of an ELF64 little-endian file.
fn elf_section_names(bytes: &[u8]) -> Vec<String> {
    assert_eq!(&bytes[..6], b"\x7fELF\x02\x01", "an ELF64 little-endian file");
    let u16_at = |o: usize| u16::from_le_bytes(bytes[o..o + 2].try_into().unwrap()) as usize;
    let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().unwrap()) as usize;
    let (shoff, shentsize, shnum, shstrndx) = (u64_at(0x28), u16_at(0x3a), u16_at(0x3c), u16_at(0x3e));
    let header = |i: usize| shoff + i * shentsize;
    let strtab = u64_at(header(shstrndx) + 0x18);
    (0..shnum)
        .map(|i| {
            let name = strtab + u32::from_le_bytes(bytes[header(i)..header(i) + 4].try_into().unwrap()) as usize;
            let end = name + bytes[name..].iter().position(|b| *b == 0).unwrap();
            String::from_utf8_lossy(&bytes[name..end]).into_owned()
        })
        .collect()
}

fn cargo() -> Command {
    Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
}

fn run_ok(c: &mut Command) -> Output {
    let o = c.output().unwrap_or_else(|e| panic!("{c:?}: {e}"));
    assert!(o.status.success(), "{c:?}: {}", text(&o));
    o
}

#[test]
fn the_package_builds_unpacks_and_runs() {
    let name = "the_package_builds_unpacks_and_runs";
    if !cargo().args(["deb", "--version"]).output().is_ok_and(|o| o.status.success()) {
        let note = "no cargo-deb: `cargo install cargo-deb --locked` (docs/guide/install.md)";
        if std::env::var_os("TOPSPIN_REQUIRE_CARGO_DEB").is_some_and(|v| v == "1") {
            panic!("{note} (TOPSPIN_REQUIRE_CARGO_DEB=1)");
        }
        return skipped(name, note);
    }
    if !have("dpkg-deb") {
        return skipped(name, "no dpkg-deb on this machine");
    }
    // This build's binary: target/<profile>/topspin → the target dir.
    let bin = Path::new(env!("CARGO_BIN_EXE_topspin"));
    let profile_dir = bin.parent().unwrap();
    let target_dir = profile_dir.parent().unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let deb = tmp.path().join("topspin.deb");
    run_ok(
        cargo()
            .current_dir(root())
            .env("CARGO_TARGET_DIR", target_dir)
            .args(["deb", "--no-build", "--fast", "--profile"])
            .arg(profile_dir.file_name().unwrap())
            .arg("--output")
            .arg(&deb),
    );

    // The paths.
    let contents = String::from_utf8(run_ok(Command::new("dpkg-deb").arg("--contents").arg(&deb)).stdout).unwrap();
    let paths: Vec<&str> = contents.lines().map(|l| l.split_whitespace().nth(5).unwrap()).collect();
    let meta = deb_metadata();
    let mut expected: Vec<String> =
        assets(&meta).iter().map(|(s, d, _)| format!("./{}", installed_path(s, d))).collect();
    expected.extend(
        [
            "./usr/lib/systemd/system/topspin.service",
            "./usr/lib/sysusers.d/topspin.conf",
            "./usr/lib/tmpfiles.d/topspin.conf",
            "./usr/share/doc/topspin/copyright",
        ]
        .map(String::from),
    );
    for p in &expected {
        assert!(paths.contains(&p.as_str()), "{p} not in the package:\n{contents}");
    }
    for l in contents.lines().filter(|l| !l.starts_with('d')) {
        let owner = l.split_whitespace().nth(1).unwrap();
        assert_eq!(owner, "0/0", "owned by root: {l}");
    }

    // The control part: conffiles, dependencies, maintainer scripts.
    let control = tmp.path().join("DEBIAN");
    run_ok(Command::new("dpkg-deb").arg("-e").arg(&deb).arg(&control));
    let conffiles = std::fs::read_to_string(control.join("conffiles")).unwrap();
    assert_eq!(conffiles.lines().collect::<Vec<_>>(), ["/etc/topspin/topspin.toml"]);
    let ctl = std::fs::read_to_string(control.join("control")).unwrap();
    let depends = ctl.lines().find_map(|l| l.strip_prefix("Depends: ")).unwrap_or_else(|| panic!("{ctl}"));
    assert!(depends.contains("libc6") && depends.contains("systemd"), "{depends}");
    for script in ["postinst", "prerm", "postrm"] {
        let p = control.join(script);
        let body = std::fs::read_to_string(&p).unwrap_or_else(|_| panic!("no {script} in the package"));
        assert!(!body.contains("#DEBHELPER#"), "{script}: token not replaced");
        let o = Command::new("sh").arg("-n").arg(&p).output().unwrap();
        assert!(o.status.success(), "sh -n {script}: {}", text(&o));
    }
    let postinst = std::fs::read_to_string(control.join("postinst")).unwrap();
    assert!(postinst.contains("systemd-sysusers ${DPKG_ROOT:+--root=\"$DPKG_ROOT\"} topspin.conf"), "{postinst}");
    assert!(postinst.contains("systemd-tmpfiles --create topspin.conf"), "{postinst}");
    // Neither enabled nor started on install; restarted on upgrade if running.
    assert!(!postinst.contains("deb-systemd-invoke start"), "{postinst}");
    assert!(postinst.contains("deb-systemd-invoke try-restart topspin.service"), "{postinst}");
    for script in ["postinst", "postrm", "prerm"] {
        let body = std::fs::read_to_string(control.join(script)).unwrap();
        assert!(body.starts_with("#!/bin/sh\nset -e\n"), "{script}:\n{body}");
    }
    let postrm = std::fs::read_to_string(control.join("postrm")).unwrap();
    assert!(postrm.contains("rmdir --ignore-fail-on-non-empty /var/lib/topspin"), "{postrm}");
    assert!(postrm.contains("deb-systemd-helper purge topspin.service"), "{postrm}");

    // Unpacked into a scratch root.
    let scratch = tmp.path().join("root");
    run_ok(Command::new("dpkg-deb").arg("-x").arg(&deb).arg(&scratch));
    let etc = scratch.join("etc/topspin/topspin.toml");
    assert_eq!(std::fs::read(&etc).unwrap(), std::fs::read(root().join("deploy/topspin.toml")).unwrap());
    let unit = std::fs::read_to_string(scratch.join("usr/lib/systemd/system/topspin.service")).unwrap();
    assert_eq!(unit, std::fs::read_to_string(root().join("deploy/topspin.service")).unwrap());
    let shipped = scratch.join("usr/bin/topspin");
    let sections = elf_section_names(&std::fs::read(&shipped).unwrap());
    assert!(sections.iter().any(|s| s == ".text"), "{sections:?}");
    assert!(!sections.iter().any(|s| s.starts_with(".debug_")), "debug info in /usr/bin/topspin: {sections:?}");

    let topspin = || {
        let mut c = Command::new(&shipped);
        for (k, _) in std::env::vars().filter(|(k, _)| k.starts_with("TOPSPIN_")) {
            c.env_remove(k);
        }
        c.current_dir(&scratch);
        c
    };
    let v = run_ok(topspin().arg("--version"));
    assert_eq!(String::from_utf8_lossy(&v.stdout).trim(), format!("topspin {}", env!("CARGO_PKG_VERSION")));
    // The packaged configuration is usable: doctor's verdicts may fail on
    // this machine (exit 1), the configuration may not (exit 2).
    let o = topspin().args(["doctor", "--json", "--probe-seconds", "0.3", "--config"]).arg(&etc).output().unwrap();
    assert!(matches!(o.status.code(), Some(0 | 1)), "doctor on the packaged configuration: {}", text(&o));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(report["checks"].as_array().is_some_and(|c| !c.is_empty()), "{report}");
    let o = run_ok(topspin().args(["run", "--print-config", "--config"]).arg(&etc));
    let printed = topspin_daemon::config::DaemonConfig::from_toml(&String::from_utf8_lossy(&o.stdout)).unwrap();
    assert_eq!(printed, topspin_daemon::config::DaemonConfig::default());
    // The shipped calibration loads and is the compiled-in one.
    let calib = scratch.join("usr/share/topspin/calib");
    let from_files = run_ok(topspin().args(["calibrate", "cell", "--list-points", "--json", "--calib"]).arg(&calib));
    let compiled_in = run_ok(topspin().args(["calibrate", "cell", "--list-points", "--json"]));
    assert_eq!(from_files.stdout, compiled_in.stdout);

    // The package's own sysusers and tmpfiles files, as the postinst runs them.
    if have("systemd-sysusers") && have("systemd-tmpfiles") && is_root() {
        let s = scratch.join("usr/lib/sysusers.d/topspin.conf");
        let t = scratch.join("usr/lib/tmpfiles.d/topspin.conf");
        make_user_and_state_dir(&scratch, &s, &t);
    }
    if have("systemd-analyze") {
        let d = tmp.path().join("unit");
        std::fs::create_dir(&d).unwrap();
        assert_verifies(&unit_with_program(&unit, &shipped, &d));
    }
}
