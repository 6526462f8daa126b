//! systemd integration for `Type=notify` services (see `deploy/`): readiness,
//! the watchdog and stopping, sent as `sd_notify(3)` datagrams to
//! `$NOTIFY_SOCKET`. Every call is a no-op returning `Ok` when the process
//! was not started by systemd (no `NOTIFY_SOCKET`), so the daemon calls them
//! unconditionally.
//!
//! Cold path: each call formats and sends one small datagram (it may
//! allocate); call from the main or telemetry thread, never a hot loop. The
//! watchdog should be fed by a thread that first checks the hot threads made
//! progress, at half of [`watchdog_interval`].

use std::ffi::OsString;
use std::io;
use std::os::unix::net::UnixDatagram;
use std::time::Duration;

/// Where notifications go, read from the environment once or given.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Notifier {
    socket: Option<OsString>,
    watchdog: Option<Duration>,
}

impl Notifier {
    /// From `NOTIFY_SOCKET`, `WATCHDOG_USEC` and `WATCHDOG_PID`.
    pub fn from_env() -> Self {
        let watchdog_pid = std::env::var("WATCHDOG_PID").ok();
        Self::new(
            std::env::var_os("NOTIFY_SOCKET"),
            std::env::var("WATCHDOG_USEC").ok().as_deref(),
            watchdog_pid.as_deref(),
            std::process::id(),
        )
    }

    /// From the variables' values: `socket` a path or `@abstract` name,
    /// `watchdog_usec` and `watchdog_pid` as systemd sets them; the watchdog
    /// counts only when `watchdog_pid` is absent or equals `pid`.
    pub fn new(socket: Option<OsString>, watchdog_usec: Option<&str>, watchdog_pid: Option<&str>, pid: u32) -> Self {
        let for_us = watchdog_pid.is_none_or(|p| p.trim().parse::<u32>().ok() == Some(pid));
        let watchdog = watchdog_usec
            .and_then(|u| u.trim().parse::<u64>().ok())
            .filter(|&u| u > 0 && for_us)
            .map(Duration::from_micros);
        Notifier { socket: socket.filter(|s| !s.is_empty()), watchdog }
    }

    /// Whether a service manager listens.
    pub fn enabled(&self) -> bool {
        self.socket.is_some()
    }

    /// The watchdog timeout systemd expects pings within (`WatchdogSec=`),
    /// if enabled for this process. Ping at half of it.
    pub fn watchdog_interval(&self) -> Option<Duration> {
        self.watchdog
    }

    /// Sends one notification (newline-separated `KEY=VALUE` lines).
    pub fn send(&self, state: &str) -> io::Result<()> {
        let Some(path) = &self.socket else { return Ok(()) };
        let sock = UnixDatagram::unbound()?;
        let bytes = path.as_encoded_bytes();
        if let Some(name) = bytes.strip_prefix(b"@") {
            use std::os::linux::net::SocketAddrExt;
            let addr = std::os::unix::net::SocketAddr::from_abstract_name(name)?;
            sock.connect_addr(&addr)?;
        } else {
            sock.connect(path)?;
        }
        let n = sock.send(state.as_bytes())?;
        if n != state.len() {
            return Err(io::Error::new(io::ErrorKind::WriteZero, "short sd_notify datagram"));
        }
        Ok(())
    }

    /// `READY=1`: start-up is done (sockets bound, threads running).
    pub fn ready(&self) -> io::Result<()> {
        self.send("READY=1\n")
    }

    /// `WATCHDOG=1`: the daemon is alive.
    pub fn watchdog(&self) -> io::Result<()> {
        self.send("WATCHDOG=1\n")
    }

    /// `STOPPING=1`: shutting down.
    pub fn stopping(&self) -> io::Result<()> {
        self.send("STOPPING=1\n")
    }

    /// `STATUS=…`: one line shown by `systemctl status` (newlines are replaced).
    pub fn status(&self, text: &str) -> io::Result<()> {
        self.send(&format!("STATUS={}\n", text.replace('\n', " ")))
    }
}

/// `READY=1` to `$NOTIFY_SOCKET`; a no-op without it.
pub fn notify_ready() -> io::Result<()> {
    Notifier::from_env().ready()
}

/// `WATCHDOG=1` to `$NOTIFY_SOCKET`; a no-op without it.
pub fn notify_watchdog() -> io::Result<()> {
    Notifier::from_env().watchdog()
}

/// `STOPPING=1` to `$NOTIFY_SOCKET`; a no-op without it.
pub fn notify_stopping() -> io::Result<()> {
    Notifier::from_env().stopping()
}

/// The watchdog timeout systemd set for this process (`WATCHDOG_USEC`,
/// when `WATCHDOG_PID` is absent or ours); `None` when the watchdog is off.
pub fn watchdog_interval() -> Option<Duration> {
    Notifier::from_env().watchdog_interval()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_a_socket_every_call_is_a_no_op() {
        let n = Notifier::new(None, None, None, 1);
        assert!(!n.enabled());
        assert!(n.ready().is_ok() && n.watchdog().is_ok() && n.stopping().is_ok() && n.status("x").is_ok());
        assert_eq!(n.watchdog_interval(), None);
        // An empty NOTIFY_SOCKET counts as unset.
        assert!(!Notifier::new(Some(OsString::new()), None, None, 1).enabled());
        // The process-wide helpers, when the test runner is not under systemd.
        if std::env::var_os("NOTIFY_SOCKET").is_none() {
            assert!(notify_ready().is_ok() && notify_watchdog().is_ok() && notify_stopping().is_ok());
        }
    }

    #[test]
    fn watchdog_only_for_our_pid() {
        let us = |pid| Notifier::new(None, Some("2000000"), pid, 42).watchdog_interval();
        assert_eq!(us(None), Some(Duration::from_secs(2)));
        assert_eq!(us(Some("42")), Some(Duration::from_secs(2)));
        assert_eq!(us(Some("41")), None);
        assert_eq!(Notifier::new(None, Some("0"), None, 42).watchdog_interval(), None);
        assert_eq!(Notifier::new(None, Some("x"), None, 42).watchdog_interval(), None);
    }

    #[test]
    fn datagrams_reach_the_socket() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("notify");
        let server = UnixDatagram::bind(&path).unwrap();
        let n = Notifier::new(Some(path.clone().into_os_string()), None, None, 1);
        n.ready().unwrap();
        n.status("tracking\nball 3").unwrap();
        n.watchdog().unwrap();
        let mut buf = [0u8; 256];
        let mut got = Vec::new();
        for _ in 0..3 {
            let k = server.recv(&mut buf).unwrap();
            got.push(String::from_utf8_lossy(&buf[..k]).into_owned());
        }
        assert_eq!(got, ["READY=1\n", "STATUS=tracking ball 3\n", "WATCHDOG=1\n"]);
        // Nobody listening: an error, which the daemon logs and ignores.
        drop(server);
        assert!(n.stopping().is_err());
    }
}
