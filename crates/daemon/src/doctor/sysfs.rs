//! The files `topspin doctor` reads, under a root folder: [`SysRoot`] is
//! `/` on the PC and a fake `/proc` + `/sys` tree in a temporary folder in
//! the tests, so every check runs the same code against both. Also the
//! small parsers those files need: kernel CPU lists (`0-3,5`) and kernel
//! command-line parameters.
//!
//! Reads only; a file that cannot be read is an [`Unreadable`] naming it
//! (the check then says `warn` and why), never a panic.

use std::collections::BTreeSet;
use std::fmt;
use std::path::{Path, PathBuf};

/// A folder standing for `/`: absolute paths such as `/proc/cmdline` are
/// read under it.
#[derive(Clone, Debug)]
pub struct SysRoot {
    root: PathBuf,
}

/// A file or folder that could not be read; Display is one line naming the
/// absolute path (as on the PC, not the fake root) and the OS's reason.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Unreadable {
    /// The absolute path on the PC.
    pub path: String,
    /// The OS's reason.
    pub reason: String,
}

impl fmt::Display for Unreadable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "cannot read {}: {}", self.path, self.reason)
    }
}

impl SysRoot {
    /// The PC itself.
    pub fn live() -> Self {
        SysRoot { root: PathBuf::from("/") }
    }

    /// A fake tree: `root/proc/…`, `root/sys/…`, `root/run/…`.
    pub fn new(root: impl Into<PathBuf>) -> Self {
        SysRoot { root: root.into() }
    }

    /// Where the absolute path `abs` lies under this root.
    pub fn path(&self, abs: &str) -> PathBuf {
        self.root.join(abs.trim_start_matches('/'))
    }

    fn unreadable(abs: &str, e: &std::io::Error) -> Unreadable {
        let reason = match e.kind() {
            std::io::ErrorKind::NotFound => "no such file".to_owned(),
            std::io::ErrorKind::PermissionDenied => "permission denied".to_owned(),
            _ => e.to_string(),
        };
        Unreadable { path: abs.to_owned(), reason }
    }

    /// The whole file.
    pub fn read(&self, abs: &str) -> Result<String, Unreadable> {
        std::fs::read_to_string(self.path(abs)).map_err(|e| Self::unreadable(abs, &e))
    }

    /// The file with surrounding white space removed (sysfs values end in a
    /// newline).
    pub fn read_trim(&self, abs: &str) -> Result<String, Unreadable> {
        self.read(abs).map(|s| s.trim().to_owned())
    }

    /// Whether `abs` exists (a file or a folder).
    pub fn exists(&self, abs: &str) -> bool {
        self.path(abs).exists()
    }

    /// The names in a folder, sorted.
    pub fn list(&self, abs: &str) -> Result<Vec<String>, Unreadable> {
        let dir = std::fs::read_dir(self.path(abs)).map_err(|e| Self::unreadable(abs, &e))?;
        let mut names: Vec<String> =
            dir.filter_map(|e| e.ok()).map(|e| e.file_name().to_string_lossy().into_owned()).collect();
        names.sort();
        Ok(names)
    }

    /// The root folder itself.
    pub fn root(&self) -> &Path {
        &self.root
    }
}

/// The process ids in `/proc` (empty when it cannot be listed).
pub(crate) fn pids(root: &SysRoot) -> Vec<u32> {
    root.list("/proc").map(|names| names.iter().filter_map(|n| n.parse().ok()).collect()).unwrap_or_default()
}

/// A set of CPU numbers.
pub(crate) type CpuSet = BTreeSet<usize>;

/// Parses a kernel CPU list (`0-3,5,8-9`, as in `/sys/devices/system/cpu/online`
/// or `isolcpus=`); empty text, `(null)` (an empty `nohz_full`) and white
/// space give the empty set. `None` for anything else.
pub(crate) fn parse_cpu_list(text: &str) -> Option<CpuSet> {
    let text = text.trim();
    let mut set = CpuSet::new();
    if text.is_empty() || text == "(null)" {
        return Some(set);
    }
    for part in text.split(',') {
        let part = part.trim();
        // A range may carry a stride: `0-7:2` (every other CPU).
        let (range, stride) = match part.split_once(':') {
            Some((r, s)) => (r, s.parse::<usize>().ok().filter(|s| *s > 0)?),
            None => (part, 1),
        };
        match range.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (a.parse::<usize>().ok()?, b.parse::<usize>().ok()?);
                if a > b || b > crate::config::MAX_CORE {
                    return None;
                }
                set.extend((a..=b).step_by(stride));
            }
            None => {
                let c = range.parse::<usize>().ok()?;
                if c > crate::config::MAX_CORE {
                    return None;
                }
                set.insert(c);
            }
        }
    }
    Some(set)
}

/// A CPU set the way the kernel writes it (`0-3,5`); `none` when empty.
pub(crate) fn format_cpu_list(set: &CpuSet) -> String {
    if set.is_empty() {
        return "none".to_owned();
    }
    let mut parts = Vec::new();
    let mut it = set.iter().copied().peekable();
    while let Some(start) = it.next() {
        let mut end = start;
        while it.peek() == Some(&(end + 1)) {
            end += 1;
            it.next();
        }
        parts.push(if end == start { start.to_string() } else { format!("{start}-{end}") });
    }
    parts.join(",")
}

/// The value of the last `key=value` on a kernel command line (the kernel
/// takes the last), before a `--` (what follows goes to init).
pub(crate) fn cmdline_param<'a>(cmdline: &'a str, key: &str) -> Option<&'a str> {
    cmdline
        .split_whitespace()
        .take_while(|w| *w != "--")
        .filter_map(|w| w.split_once('='))
        .filter(|(k, _)| *k == key)
        .map(|(_, v)| v)
        .last()
}

/// The CPUs of an `isolcpus=` value, which may start with flags
/// (`isolcpus=nohz,domain,managed_irq,2-3`).
pub(crate) fn isolcpus_cpus(value: &str) -> Option<CpuSet> {
    let cpus: Vec<&str> =
        value.split(',').skip_while(|p| p.chars().next().is_some_and(|c| c.is_ascii_alphabetic())).collect();
    parse_cpu_list(&cpus.join(","))
}

/// One `Key:\tvalue` line of a `/proc/<pid>/status` file.
pub(crate) fn status_field<'a>(status: &'a str, key: &str) -> Option<&'a str> {
    status.lines().find_map(|l| l.strip_prefix(key).and_then(|r| r.strip_prefix(':')).map(str::trim))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(v: &[usize]) -> CpuSet {
        v.iter().copied().collect()
    }

    #[test]
    fn cpu_lists_parse_and_print_as_the_kernel_writes_them() {
        assert_eq!(parse_cpu_list("0-3,5\n"), Some(set(&[0, 1, 2, 3, 5])));
        assert_eq!(parse_cpu_list("0-7:2"), Some(set(&[0, 2, 4, 6])));
        assert_eq!(parse_cpu_list(""), Some(set(&[])));
        assert_eq!(parse_cpu_list("(null)\n"), Some(set(&[])));
        assert_eq!(parse_cpu_list("3-1"), None);
        assert_eq!(parse_cpu_list("x"), None);
        assert_eq!(parse_cpu_list("2000"), None);
        assert_eq!(format_cpu_list(&set(&[0, 1, 2, 3, 5, 7, 8])), "0-3,5,7-8");
        assert_eq!(format_cpu_list(&set(&[])), "none");
    }

    #[test]
    fn command_line_parameters_take_the_last_before_init_arguments() {
        let c = "BOOT_IMAGE=/vmlinuz isolcpus=1 quiet isolcpus=managed_irq,domain,2-3 nohz_full=2-3 -- isolcpus=9";
        assert_eq!(cmdline_param(c, "isolcpus"), Some("managed_irq,domain,2-3"));
        assert_eq!(cmdline_param(c, "nohz_full"), Some("2-3"));
        assert_eq!(cmdline_param(c, "rcu_nocbs"), None);
        assert_eq!(isolcpus_cpus("managed_irq,domain,2-3"), Some(set(&[2, 3])));
        assert_eq!(isolcpus_cpus("1,3"), Some(set(&[1, 3])));
    }

    #[test]
    fn a_missing_file_is_named_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let root = SysRoot::new(dir.path());
        let e = root.read("/proc/cmdline").unwrap_err();
        assert_eq!(e.to_string(), "cannot read /proc/cmdline: no such file");
        std::fs::create_dir_all(dir.path().join("proc")).unwrap();
        std::fs::write(dir.path().join("proc/cmdline"), "quiet\n").unwrap();
        assert_eq!(root.read_trim("/proc/cmdline").unwrap(), "quiet");
        assert_eq!(status_field("Name:\ttopspin\nCapEff:\t0000000000804000\n", "CapEff"), Some("0000000000804000"));
    }
}
