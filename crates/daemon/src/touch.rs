//! The RSI listener of `topspin calibrate cell --rsi`: binds the sensor's
//! address, answers every `<Rob>` at once with a zero correction (`RKorr`
//! all zeros, the request's IPOC echoed), so RSI keeps running while the
//! robot stands or is moved by its own program, and hands the `RIst` of
//! the requests that follow a [`TouchListener::take`] to the caller.
//!
//! One thread owns the socket; the caller waits on a channel. A take
//! first drops what the socket queued before it (answered, not used), so
//! the samples are those the robot sent after the caller asked. The
//! still-check and the fit are the core's
//! ([`topspin_core::calib::cell::average_still`]). It does not run the
//! strike session ([`crate::rsi_server`]) and never commands motion.

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::thread::JoinHandle;

use topspin_core::rsi::{Axes, KukaPose, RobFrame, SenFrame};

use crate::rsi_server::MAX_REQUEST_LEN;

/// Decimals of the zero corrections.
const PRECISION: u8 = 4;
/// How often the thread looks at its stop flag while no request comes.
const STOP_POLL: std::time::Duration = std::time::Duration::from_millis(20);

/// Why a take gave no samples.
#[derive(Debug, thiserror::Error)]
pub enum TouchError {
    /// Not enough requests arrived in time.
    #[error("the robot sent {got} of {want} RSI requests in {waited_s} s: is RSI on and sending to this address?")]
    Silent {
        /// Samples received.
        got: usize,
        /// Samples asked for.
        want: usize,
        /// How long the take waited, s.
        waited_s: f64,
    },
    /// The requests carry no `RIst` (the SEND list of the Ethernet
    /// configuration lacks it).
    #[error("the RSI requests carry no <RIst>: add it to the SEND list of the Ethernet configuration")]
    NoRist,
    /// The socket thread ended (a socket error).
    #[error("the RSI listener stopped: {0}")]
    Stopped(String),
}

enum Sample {
    Rist(KukaPose, Option<Axes>),
    NoRist,
}

/// The listener: a thread that answers RSI, and the caller's end.
#[derive(Debug)]
pub struct TouchListener {
    local_addr: SocketAddr,
    stop: Arc<AtomicBool>,
    wanted: Arc<AtomicUsize>,
    drain: Arc<AtomicBool>,
    answered: Arc<AtomicU64>,
    samples: Receiver<Sample>,
    join: Option<JoinHandle<io::Result<()>>>,
}

impl std::fmt::Debug for Sample {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Sample::Rist(p, a) => write!(f, "Rist({p:?}, {a:?})"),
            Sample::NoRist => write!(f, "NoRist"),
        }
    }
}

impl TouchListener {
    /// Binds `addr` and starts answering with `sentype` (the Ethernet
    /// configuration's SENTYPE).
    pub fn bind(addr: SocketAddr, sentype: &str) -> io::Result<Self> {
        topspin_core::rsi::check_text(sentype)
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, format!("SENTYPE {sentype:?}: {e}")))?;
        let socket = UdpSocket::bind(addr)?;
        socket.set_read_timeout(Some(STOP_POLL))?;
        let local_addr = socket.local_addr()?;
        let (tx, samples) = channel();
        let stop = Arc::new(AtomicBool::new(false));
        let wanted = Arc::new(AtomicUsize::new(0));
        let drain = Arc::new(AtomicBool::new(false));
        let answered = Arc::new(AtomicU64::new(0));
        let shared = (stop.clone(), wanted.clone(), drain.clone(), answered.clone());
        let sentype = sentype.to_owned();
        let join = std::thread::Builder::new()
            .name("rsi-touch".into())
            .spawn(move || answer_loop(&socket, &sentype, &tx, shared))?;
        Ok(TouchListener { local_addr, stop, wanted, drain, answered, samples, join: Some(join) })
    }

    /// The bound address.
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// Requests answered so far.
    pub fn answered(&self) -> u64 {
        self.answered.load(Ordering::Relaxed)
    }

    /// The TCP positions (`RIst` X, Y, Z, mm) of the next `n` requests
    /// that arrive after this call, waiting at most `timeout` in all.
    pub fn take(&mut self, n: usize, timeout: std::time::Duration) -> Result<Vec<[f64; 3]>, TouchError> {
        Ok(self.take_requests(n, timeout)?.iter().map(|(p, _)| [p.x, p.y, p.z]).collect())
    }

    /// `RIst` and `AIPos` (where the SEND list has it) of the next `n`
    /// requests that arrive after this call, waiting at most `timeout`.
    pub fn take_requests(
        &mut self,
        n: usize,
        timeout: std::time::Duration,
    ) -> Result<Vec<(KukaPose, Option<Axes>)>, TouchError> {
        while self.samples.try_recv().is_ok() {} // a timed-out take's leftovers
        self.drain.store(true, Ordering::Release);
        self.wanted.store(n, Ordering::Release);
        let mut out = Vec::with_capacity(n);
        let mut left = timeout;
        let step = std::time::Duration::from_millis(50);
        while out.len() < n {
            if left.is_zero() {
                self.wanted.store(0, Ordering::Release);
                return Err(TouchError::Silent { got: out.len(), want: n, waited_s: timeout.as_secs_f64() });
            }
            let wait = left.min(step);
            left -= wait;
            match self.samples.recv_timeout(wait) {
                Ok(Sample::Rist(p, a)) => out.push((p, a)),
                Ok(Sample::NoRist) => {
                    self.wanted.store(0, Ordering::Release);
                    return Err(TouchError::NoRist);
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    let why = match self.join.take().map(|j| j.join()) {
                        Some(Ok(Err(e))) => e.to_string(),
                        _ => "the thread ended".to_owned(),
                    };
                    return Err(TouchError::Stopped(why));
                }
            }
        }
        Ok(out)
    }
}

impl Drop for TouchListener {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(j) = self.join.take() {
            let _ = j.join();
        }
    }
}

type Shared = (Arc<AtomicBool>, Arc<AtomicUsize>, Arc<AtomicBool>, Arc<AtomicU64>);

/// Answers one request; its `RIst` (or its absence), `None` for what is
/// not a `<Rob>`.
fn answer(socket: &UdpSocket, sentype: &str, rx: &[u8], from: SocketAddr) -> io::Result<Option<Sample>> {
    let Ok(rob) = RobFrame::parse(rx) else { return Ok(None) };
    let sen = SenFrame {
        sentype,
        estr: Some("topspin calibrate"),
        rkorr: Some(KukaPose::default()),
        akorr: None,
        ipoc: rob.ipoc,
    };
    let mut tx = [0u8; 512];
    if let Ok(len) = sen.emit(PRECISION, &mut tx) {
        match socket.send_to(&tx[..len], from) {
            Ok(_) => {}
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
            Err(e) => return Err(e),
        }
    }
    Ok(Some(rob.rist.map_or(Sample::NoRist, |p| Sample::Rist(p, rob.aipos))))
}

fn answer_loop(socket: &UdpSocket, sentype: &str, tx: &Sender<Sample>, shared: Shared) -> io::Result<()> {
    let (stop, wanted, drain, answered) = shared;
    let mut rx = [0u8; MAX_REQUEST_LEN + 1];
    while !stop.load(Ordering::Relaxed) {
        let (n, from) = match socket.recv_from(&mut rx) {
            Ok(x) => x,
            Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => continue,
            Err(e) => return Err(e),
        };
        if n > MAX_REQUEST_LEN {
            continue;
        }
        let Some(sample) = answer(socket, sentype, &rx[..n], from)? else { continue };
        answered.fetch_add(1, Ordering::Relaxed);
        if drain.swap(false, Ordering::AcqRel) {
            // Answer (and drop) whatever queued before the take began.
            socket.set_nonblocking(true)?;
            loop {
                match socket.recv_from(&mut rx) {
                    Ok((n, from)) if n <= MAX_REQUEST_LEN => {
                        if answer(socket, sentype, &rx[..n], from)?.is_some() {
                            answered.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                    Ok(_) => {}
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                    Err(e) => return Err(e),
                }
            }
            socket.set_nonblocking(false)?;
            continue;
        }
        // A drain asked for after the check above waits for the next request.
        if wanted.load(Ordering::Acquire) > 0 && !drain.load(Ordering::Acquire) {
            wanted.fetch_sub(1, Ordering::AcqRel);
            if tx.send(sample).is_err() {
                return Ok(());
            }
        }
    }
    Ok(())
}
