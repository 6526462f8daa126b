//! The sensor-side UDP loop: a thin shell that owns an [`RsiSession`],
//! binds an explicit address and answers each datagram at once.
//!
//! Wait strategy (DESIGN §10): `Blocking` sleeps in `recv_from` (cheap on
//! CPU, ≈30 µs wake-up each way across cores) or `BusyPoll` spins on a
//! non-blocking socket (≈3.5 µs, burns a core). Plans arrive through a
//! [`PlanSlot`] (latest value; the loop only ever `try_lock`s it, so it
//! never waits for the writer). The daemon's RSI thread grows out of this.

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

use super::session::{MAX_ANSWER_LEN, RsiSession, SessionEvent};
use crate::plan::StrikePlan;
use crate::runtime;

/// Largest request read, bytes.
pub const MAX_REQUEST_LEN: usize = 2048;
/// Blocking receive timeout, only to look at the stop flag.
pub const STOP_POLL: std::time::Duration = std::time::Duration::from_millis(20);

/// How the loop waits for the next datagram.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum WaitStrategy {
    Blocking,
    BusyPoll,
}

/// The latest strike plan: the writer overwrites, the reader takes the
/// newest without waiting (a contended slot is simply read next cycle).
#[derive(Debug, Default)]
pub struct PlanSlot {
    slot: Mutex<Option<StrikePlan>>,
}

impl PlanSlot {
    pub fn new() -> Self {
        Self::default()
    }

    /// Publishes `plan`, replacing any not yet taken.
    pub fn publish(&self, plan: StrikePlan) {
        let mut g = self.slot.lock().unwrap_or_else(|e| e.into_inner());
        *g = Some(plan);
    }

    /// Takes the newest plan if there is one and the slot is free now.
    pub fn try_take(&self) -> Option<StrikePlan> {
        self.slot.try_lock().ok().and_then(|mut g| g.take())
    }
}

/// The UDP loop around an [`RsiSession`].
#[derive(Debug)]
pub struct RsiServer {
    socket: UdpSocket,
    session: RsiSession,
    wait: WaitStrategy,
    rx: [u8; MAX_REQUEST_LEN],
    tx: [u8; MAX_ANSWER_LEN],
}

impl RsiServer {
    /// Binds `addr` (the IP/PORT of the Ethernet configuration).
    pub fn bind(addr: SocketAddr, session: RsiSession, wait: WaitStrategy) -> io::Result<Self> {
        let socket = UdpSocket::bind(addr)?;
        match wait {
            WaitStrategy::Blocking => socket.set_read_timeout(Some(STOP_POLL))?,
            WaitStrategy::BusyPoll => socket.set_nonblocking(true)?,
        }
        Ok(RsiServer { socket, session, wait, rx: [0; MAX_REQUEST_LEN], tx: [0; MAX_ANSWER_LEN] })
    }

    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    pub fn session(&self) -> &RsiSession {
        &self.session
    }

    pub fn into_session(self) -> RsiSession {
        self.session
    }

    /// Runs until `stop`; hands every session event to `on_event`.
    pub fn run(
        &mut self,
        stop: &AtomicBool,
        plans: &PlanSlot,
        mut on_event: impl FnMut(SessionEvent),
    ) -> io::Result<()> {
        while !stop.load(Ordering::Relaxed) {
            let (n, from) = match self.socket.recv_from(&mut self.rx) {
                Ok(x) => x,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock || e.kind() == io::ErrorKind::TimedOut => {
                    if self.wait == WaitStrategy::BusyPoll {
                        std::hint::spin_loop();
                    }
                    self.session.handle_timeout(runtime::now());
                    while let Some(e) = self.session.poll_event() {
                        on_event(e);
                    }
                    continue;
                }
                Err(e) => return Err(e),
            };
            let now = runtime::now();
            if let Some(p) = plans.try_take() {
                self.session.set_plan(p);
            }
            if let Ok(len) = self.session.handle_datagram(now, &self.rx[..n], &mut self.tx) {
                match self.socket.send_to(&self.tx[..len], from) {
                    Ok(_) => self.session.answer_sent(runtime::now()),
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                    Err(e) => return Err(e),
                }
            }
            while let Some(e) = self.session.poll_event() {
                on_event(e);
            }
        }
        Ok(())
    }
}
