//! The link between the mock controller and the sensor, and a seeded fault
//! injector around it (drop, delay, duplicate answers; reorder requests) —
//! smoltcp's `FaultInjector` pattern: the controller core has no fault `if`s.

use std::collections::VecDeque;
use std::io;
use std::net::{SocketAddr, UdpSocket};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use topspin_core::time::{Duration, Instant};
use topspin_daemon::clock;

/// Largest datagram the link carries.
pub(crate) const MAX_DATAGRAM: usize = 2048;
/// Below this much time to the deadline the receive spins instead of
/// sleeping.
pub(crate) const SPIN_WINDOW: Duration = Duration::from_micros(300);

/// Sends requests, receives answers with a deadline.
pub(crate) trait Link {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// One answer received before `deadline`, or `None`.
    fn recv_until(&mut self, deadline: Instant, buf: &mut [u8]) -> io::Result<Option<usize>>;
}

/// The real thing: UDP to the sensor's address.
#[derive(Debug)]
pub(crate) struct UdpLink {
    socket: UdpSocket,
    peer: SocketAddr,
}

impl UdpLink {
    pub(crate) fn new(bind: SocketAddr, peer: SocketAddr) -> io::Result<Self> {
        let socket = UdpSocket::bind(bind)?;
        socket.set_nonblocking(true)?;
        Ok(UdpLink { socket, peer })
    }

    pub(crate) fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }
}

impl Link for UdpLink {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        match self.socket.send_to(bytes, self.peer) {
            Ok(_) => Ok(()),
            // Nobody listening yet: the controller keeps sending.
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => Ok(()),
            Err(e) => Err(e),
        }
    }

    fn recv_until(&mut self, deadline: Instant, buf: &mut [u8]) -> io::Result<Option<usize>> {
        loop {
            match self.socket.recv_from(buf) {
                Ok((n, from)) if from == self.peer || self.peer.ip().is_unspecified() => {
                    return Ok(Some(n));
                }
                Ok(_) => continue,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock || e.kind() == io::ErrorKind::ConnectionRefused => {
                    let now = clock::now();
                    if now >= deadline {
                        return Ok(None);
                    }
                    if deadline - now > SPIN_WINDOW {
                        // Sleep in the kernel until a datagram arrives (or
                        // the spin window): woken by the arrival itself, as a
                        // controller's NIC would see it, not by a poll timer.
                        wait_readable(&self.socket, deadline - now - SPIN_WINDOW);
                    } else {
                        std::hint::spin_loop();
                    }
                }
                Err(e) => return Err(e),
            }
        }
    }
}

/// Blocks until `socket` is readable or `timeout` passed (ppoll: a
/// nanosecond timeout, woken by the datagram's arrival).
#[allow(unsafe_code)]
fn wait_readable(socket: &UdpSocket, timeout: Duration) {
    use std::os::fd::AsRawFd;
    let mut fds = libc::pollfd { fd: socket.as_raw_fd(), events: libc::POLLIN, revents: 0 };
    let ts = libc::timespec { tv_sec: (timeout.0 / 1_000_000_000) as _, tv_nsec: (timeout.0 % 1_000_000_000) as _ };
    // SAFETY: `fds` points to one valid pollfd for the call's duration, `ts`
    // is a valid timespec, and a null signal mask leaves the mask unchanged.
    unsafe {
        libc::ppoll(&mut fds, 1, &ts, std::ptr::null());
    }
}

/// Fault probabilities (each 0..1) and the delay given to delayed answers.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Faults {
    /// Probability that an answer is lost.
    pub drop: f64,
    /// Probability that an answer is held back by `delay_by`.
    pub delay: f64,
    /// How long a delayed answer is held back.
    pub delay_by: Duration,
    /// Probability that an answer is delivered twice.
    pub duplicate: f64,
    /// A request held back and sent after the next one (the sensor sees
    /// the IPOCs out of order; the held cycle goes unanswered in time).
    pub reorder: f64,
}

impl Default for Faults {
    fn default() -> Self {
        Faults { drop: 0.0, delay: 0.0, delay_by: Duration::from_millis(6), duplicate: 0.0, reorder: 0.0 }
    }
}

impl Faults {
    /// Any fault has a non-zero probability (else the link runs without the injector).
    pub fn any(&self) -> bool {
        self.drop > 0.0 || self.delay > 0.0 || self.duplicate > 0.0 || self.reorder > 0.0
    }
}

/// Wraps a link and mistreats the answers it receives.
#[derive(Debug)]
pub(crate) struct FaultInjector<L> {
    inner: L,
    faults: Faults,
    rng: ChaCha8Rng,
    held: VecDeque<(Instant, Vec<u8>)>,
    held_request: Option<Vec<u8>>,
    pub dropped: u64,
    pub delayed: u64,
    pub duplicated: u64,
    pub reordered: u64,
}

impl<L: Link> FaultInjector<L> {
    pub(crate) fn new(inner: L, faults: Faults, seed: u64) -> Self {
        FaultInjector {
            inner,
            faults,
            rng: ChaCha8Rng::seed_from_u64(seed),
            held: VecDeque::new(),
            held_request: None,
            dropped: 0,
            delayed: 0,
            duplicated: 0,
            reordered: 0,
        }
    }

    fn release(&mut self, now: Instant, buf: &mut [u8]) -> Option<usize> {
        let k = self.held.iter().position(|(t, _)| *t <= now)?;
        let (_, bytes) = self.held.remove(k)?;
        let n = bytes.len().min(buf.len());
        buf[..n].copy_from_slice(&bytes[..n]);
        Some(n)
    }
}

impl<L: Link> Link for FaultInjector<L> {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        if let Some(older) = self.held_request.take() {
            // The held request goes out after this newer one.
            self.inner.send(bytes)?;
            return self.inner.send(&older);
        }
        if self.faults.reorder > 0.0 && self.rng.random::<f64>() < self.faults.reorder {
            self.reordered += 1;
            self.held_request = Some(bytes.to_vec());
            return Ok(());
        }
        self.inner.send(bytes)
    }

    fn recv_until(&mut self, deadline: Instant, buf: &mut [u8]) -> io::Result<Option<usize>> {
        loop {
            let now = clock::now();
            if let Some(n) = self.release(now, buf) {
                return Ok(Some(n));
            }
            let next_release = self.held.iter().map(|(t, _)| *t).min();
            let until = next_release.map_or(deadline, |t| t.min(deadline));
            match self.inner.recv_until(until, buf)? {
                Some(n) => {
                    let now = clock::now();
                    let roll: f64 = self.rng.random();
                    let f = self.faults;
                    if roll < f.drop {
                        self.dropped += 1;
                    } else if roll < f.drop + f.delay {
                        self.delayed += 1;
                        self.held.push_back((now + f.delay_by, buf[..n].to_vec()));
                    } else if roll < f.drop + f.delay + f.duplicate {
                        self.duplicated += 1;
                        self.held.push_back((now, buf[..n].to_vec()));
                        return Ok(Some(n));
                    } else {
                        return Ok(Some(n));
                    }
                }
                None => {
                    if clock::now() >= deadline {
                        return Ok(None);
                    }
                }
            }
        }
    }
}
