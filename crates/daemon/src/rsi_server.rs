//! The sensor-side UDP loop: a thin shell that owns an [`RsiSession`],
//! binds an explicit address and answers each datagram at once.
//!
//! Wait strategy (DESIGN §10): `Blocking` sleeps in `recv_from` (cheap on
//! CPU, ≈30 µs wake-up each way across cores) or `BusyPoll` spins on a
//! non-blocking socket (≈3.5 µs, burns a core). Plans arrive through a
//! wait-free latest-value slot ([`plan_slot`]). The daemon's RSI thread
//! runs this loop.

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::clock;
use topspin_core::plan::StrikePlan;
use topspin_core::rsi::{MAX_ANSWER_LEN, RsiSession, SessionEvent};
use topspin_core::time::Instant;

/// Largest request read, bytes.
pub const MAX_REQUEST_LEN: usize = 2048;
/// Blocking receive timeout, only to look at the stop flag.
pub(crate) const STOP_POLL: std::time::Duration = std::time::Duration::from_millis(20);

/// How the loop waits for the next datagram.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum WaitStrategy {
    /// A blocking receive with a timeout of `STOP_POLL`.
    Blocking,
    /// Spin on a non-blocking socket.
    BusyPoll,
}

impl WaitStrategy {
    /// A UDP socket bound to `addr` that waits this way: a blocking
    /// receive that returns every [`STOP_POLL`], or a non-blocking one.
    pub(crate) fn bind(self, addr: SocketAddr) -> io::Result<UdpSocket> {
        let socket = UdpSocket::bind(addr)?;
        match self {
            WaitStrategy::Blocking => socket.set_read_timeout(Some(STOP_POLL))?,
            WaitStrategy::BusyPoll => socket.set_nonblocking(true)?,
        }
        Ok(socket)
    }

    /// The next datagram on `socket` into `buf`, or `None` where none came
    /// (the blocking wait timed out, or a busy poll found nothing).
    pub(crate) fn receive(self, socket: &UdpSocket, buf: &mut [u8]) -> io::Result<Option<(usize, SocketAddr)>> {
        match socket.recv_from(buf) {
            Ok(x) => Ok(Some(x)),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock || e.kind() == io::ErrorKind::TimedOut => {
                if self == WaitStrategy::BusyPoll {
                    std::hint::spin_loop();
                }
                Ok(None)
            }
            Err(e) => Err(e),
        }
    }
}

/// The writing end of the latest-value plan slot (the estimator thread).
#[derive(Debug)]
pub struct PlanWriter(triple_buffer::Input<Option<StrikePlan>>);

/// The reading end (the RSI loop): takes the newest plan, never waits, and
/// never works through a backlog of stale ones (DESIGN §4).
#[derive(Debug)]
pub struct PlanReader(triple_buffer::Output<Option<StrikePlan>>);

/// A wait-free single-producer single-consumer latest-value slot for
/// strike plans (a triple buffer: the writer overwrites, the reader sees
/// the newest complete value).
pub fn plan_slot() -> (PlanWriter, PlanReader) {
    let (input, output) = triple_buffer::triple_buffer(&None);
    (PlanWriter(input), PlanReader(output))
}

impl PlanWriter {
    /// Publishes `plan`, replacing any not yet taken.
    pub fn publish(&mut self, plan: StrikePlan) {
        self.0.write(Some(plan));
    }
}

impl PlanReader {
    /// The newest plan published since the last call, if any.
    pub fn take(&mut self) -> Option<StrikePlan> {
        if self.0.update() { *self.0.output_buffer() } else { None }
    }
}

/// What the loop reports besides answering: session events, and every
/// exchange with its timing (for telemetry and recording).
pub trait RsiSink {
    /// One event of the session.
    fn event(&mut self, e: SessionEvent);
    /// One answered request: arrival of the request, the bytes both ways,
    /// and when the answer left.
    fn exchange(&mut self, _arrival: Instant, _request: &[u8], _answer: &[u8], _sent: Instant) {}
}

impl<F: FnMut(SessionEvent)> RsiSink for F {
    fn event(&mut self, e: SessionEvent) {
        self(e)
    }
}

/// The UDP loop around an [`RsiSession`].
#[derive(Debug)]
pub struct RsiServer {
    socket: UdpSocket,
    session: RsiSession,
    wait: WaitStrategy,
    /// Only requests from this address are answered.
    allowed: Option<std::net::IpAddr>,
    /// Requests from other addresses, ignored.
    foreign: u64,
    /// Requests longer than [`MAX_REQUEST_LEN`], ignored (not truncated
    /// into something that might parse).
    oversized: u64,
    /// One byte more than a request may hold: a datagram that fills it
    /// was too long.
    rx: [u8; MAX_REQUEST_LEN + 1],
    tx: [u8; MAX_ANSWER_LEN],
}

impl RsiServer {
    /// Binds `addr` (the IP/PORT of the Ethernet configuration).
    pub fn bind(addr: SocketAddr, session: RsiSession, wait: WaitStrategy) -> io::Result<Self> {
        Ok(RsiServer {
            socket: wait.bind(addr)?,
            session,
            wait,
            allowed: None,
            foreign: 0,
            oversized: 0,
            rx: [0; MAX_REQUEST_LEN + 1],
            tx: [0; MAX_ANSWER_LEN],
        })
    }

    /// Answers only requests from `ip` (the controller); others are
    /// ignored and counted.
    pub fn allow_only(&mut self, ip: std::net::IpAddr) {
        self.allowed = Some(ip);
    }

    /// Requests ignored because they came from another address.
    pub fn foreign(&self) -> u64 {
        self.foreign
    }

    /// Requests ignored because they were longer than [`MAX_REQUEST_LEN`].
    pub fn oversized(&self) -> u64 {
        self.oversized
    }

    /// The address the socket is bound to.
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// The RSI session the loop drives.
    pub fn session(&self) -> &RsiSession {
        &self.session
    }

    /// Ends the loop, giving back its RSI session.
    pub fn into_session(self) -> RsiSession {
        self.session
    }

    /// Runs until `stop`; hands every session event to `on_event`.
    pub fn run(&mut self, stop: &AtomicBool, plans: &mut PlanReader, mut sink: impl RsiSink) -> io::Result<()> {
        while !stop.load(Ordering::Relaxed) {
            let Some((n, from)) = self.wait.receive(&self.socket, &mut self.rx)? else {
                self.session.handle_timeout(clock::now());
                while let Some(e) = self.session.poll_event() {
                    sink.event(e);
                }
                continue;
            };
            let now = clock::now();
            if self.allowed.is_some_and(|ip| ip != from.ip()) {
                self.foreign += 1;
                continue;
            }
            if n > MAX_REQUEST_LEN {
                self.oversized += 1;
                continue;
            }
            if let Some(p) = plans.take() {
                self.session.set_plan(p);
            }
            if let Ok(len) = self.session.handle_datagram(now, &self.rx[..n], &mut self.tx) {
                match self.socket.send_to(&self.tx[..len], from) {
                    Ok(_) => {
                        let sent = clock::now();
                        self.session.answer_sent(sent);
                        sink.exchange(now, &self.rx[..n], &self.tx[..len], sent);
                    }
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                    Err(e) => return Err(e),
                }
            }
            while let Some(e) = self.session.poll_event() {
                sink.event(e);
            }
        }
        Ok(())
    }
}
