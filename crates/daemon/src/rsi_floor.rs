//! The floor: the least an RSI server can do for a KR C4 — copy the
//! request's IPOC into a constant `<Sen>` answer and send it — on the same
//! socket, wait strategy and thread placement as [`crate::rsi_server`].
//! `topspin bench latency --floor` runs it against the same mock KR C4 in
//! the same run, so that each RSI answer time is also a ratio over what
//! this machine allows. It records what the RSI server records: the time
//! from `recvfrom` returning to `sendto` returning. No parsing beyond
//! finding `<IPOC>`, no session, no allocation in the loop.

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};

use hdrhistogram::Histogram;

use crate::clock;
use crate::rsi_server::{MAX_REQUEST_LEN, WaitStrategy};

/// The answer up to the IPOC's digits.
const HEAD: &[u8] = b"<Sen Type=\"ImFree\"><EStr>floor</EStr><RKorr X=\"0.0000\" Y=\"0.0000\" Z=\"0.0000\" \
A=\"0.0000\" B=\"0.0000\" C=\"0.0000\"/><IPOC>";
/// After them.
const TAIL: &[u8] = b"</IPOC></Sen>";
/// The longest IPOC copied (u64 has 20 digits).
const MAX_DIGITS: usize = 20;
/// Room for the longest answer.
pub const ANSWER_CAP: usize = HEAD.len() + MAX_DIGITS + TAIL.len();

/// The digits between `<IPOC>` and `</IPOC>`, if any.
pub fn ipoc_digits(request: &[u8]) -> Option<&[u8]> {
    let open = b"<IPOC>";
    let start = request.windows(open.len()).position(|w| w == open)? + open.len();
    let rest = &request[start..];
    let end = rest.iter().position(|&b| b == b'<')?;
    let digits = rest[..end].trim_ascii();
    (!digits.is_empty() && digits.len() <= MAX_DIGITS && digits.iter().all(u8::is_ascii_digit)).then_some(digits)
}

/// Writes the constant answer for `digits` into `out`; its length.
pub fn answer(digits: &[u8], out: &mut [u8; ANSWER_CAP]) -> usize {
    let n = HEAD.len() + digits.len() + TAIL.len();
    out[..HEAD.len()].copy_from_slice(HEAD);
    out[HEAD.len()..HEAD.len() + digits.len()].copy_from_slice(digits);
    out[HEAD.len() + digits.len()..n].copy_from_slice(TAIL);
    n
}

/// The floor server (see the module doc).
#[derive(Debug)]
pub struct FloorServer {
    socket: UdpSocket,
    wait: WaitStrategy,
    rx: [u8; MAX_REQUEST_LEN + 1],
    tx: [u8; ANSWER_CAP],
    /// recvfrom returned → sendto returned, ns.
    pub answer_ns: Histogram<u64>,
    /// Requests without an IPOC (not answered).
    pub unanswerable: u64,
}

impl FloorServer {
    /// Binds `addr` with the RSI server's socket options for `wait`.
    pub fn bind(addr: SocketAddr, wait: WaitStrategy) -> io::Result<Self> {
        let socket = wait.bind(addr)?;
        let answer_ns = Histogram::new_with_bounds(1, 60_000_000_000, 3).map_err(io::Error::other)?;
        Ok(FloorServer { socket, wait, rx: [0; MAX_REQUEST_LEN + 1], tx: [0; ANSWER_CAP], answer_ns, unanswerable: 0 })
    }

    /// The address the socket is bound to.
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// Answers until `stop`.
    pub fn run(&mut self, stop: &AtomicBool) -> io::Result<()> {
        while !stop.load(Ordering::Relaxed) {
            let Some((n, from)) = self.wait.receive(&self.socket, &mut self.rx)? else { continue };
            let now = clock::now();
            let Some(digits) = ipoc_digits(&self.rx[..n.min(MAX_REQUEST_LEN)]) else {
                self.unanswerable += 1;
                continue;
            };
            let len = answer(digits, &mut self.tx);
            match self.socket.send_to(&self.tx[..len], from) {
                Ok(_) => {
                    let _ = self.answer_ns.record((clock::now() - now).0.max(1));
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use topspin_core::rsi::SenFrame;

    #[test]
    fn the_ipoc_is_copied_into_an_answer_the_controller_takes() {
        let req =
            b"<Rob Type=\"KUKA\"><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"0\" B=\"0\" C=\"0\"/><IPOC> 4208831 </IPOC></Rob>";
        let d = ipoc_digits(req).unwrap();
        let mut out = [0u8; ANSWER_CAP];
        let n = answer(d, &mut out);
        let sen = SenFrame::parse(&out[..n]).unwrap();
        assert_eq!(sen.ipoc, 4_208_831);
        assert_eq!(sen.sentype, b"ImFree");
        assert_eq!(sen.rkorr.map(|k| k.to_array()), Some([0.0; 6]));
        assert_eq!(ipoc_digits(b"<Rob><IPOC>12a</IPOC></Rob>"), None);
        assert_eq!(ipoc_digits(b"<Rob></Rob>"), None);
        assert_eq!(ipoc_digits(&[b'9'; 40]), None);
        let long = b"<Rob><IPOC>123456789012345678901</IPOC></Rob>";
        assert_eq!(ipoc_digits(long), None, "more digits than a u64");
    }
}
