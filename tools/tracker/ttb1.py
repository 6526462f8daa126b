#!/usr/bin/env python3
"""TTB1: the tracker's ball observation for topspin (DESIGN §5.1), plain Python.

One UDP datagram per triangulated ball, 36 bytes, little-endian:

    offset type     field
    0      [u8; 4]  magic b"TTB1"
    4      u32      sequence number (wrapping)
    8      u64      capture time, ns, the tracker's monotonic clock
    16     f32 x3   x, y, z in m, table frame
    28     f32      triangulation residual in m (NaN if unknown)
    32     u16      number of cameras that saw the ball
    34     u16      flags (bit 0: valid ball; other bits 0)

Use it as a module (``Sender``) or from the command line, which sends a
ball flying down the table at ``--rate`` Hz (a wiring check):

    python3 ttb1.py --to 127.0.0.1:41000 --count 200 --rate 200

Only the standard library: no numpy.
"""

import argparse
import math
import socket
import struct
import time

MAGIC = b"TTB1"
LENGTH = 36
FLAG_VALID = 0x0001
_FORMAT = "<4sIQffffHH"
assert struct.calcsize(_FORMAT) == LENGTH


def encode(seq, capture_ns, x, y, z, residual=float("nan"), cameras=2, valid=True):
    """The 36 bytes of one observation."""
    return struct.pack(
        _FORMAT,
        MAGIC,
        seq & 0xFFFFFFFF,
        capture_ns & 0xFFFFFFFFFFFFFFFF,
        x,
        y,
        z,
        residual,
        cameras & 0xFFFF,
        FLAG_VALID if valid else 0,
    )


class Sender:
    """Sends observations to topspin's tracker port, numbering them."""

    def __init__(self, to_host, to_port, bind=("0.0.0.0", 0)):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(bind)
        self.to = (to_host, to_port)
        self.seq = 0

    def send(self, capture_ns, x, y, z, residual=float("nan"), cameras=2, valid=True):
        """Sends one observation; capture_ns on the tracker's monotonic clock."""
        self.sock.sendto(encode(self.seq, capture_ns, x, y, z, residual, cameras, valid), self.to)
        self.seq = (self.seq + 1) & 0xFFFFFFFF

    def close(self):
        self.sock.close()


def _flight(t):
    """A plausible ball from the opponent's end towards the robot (no spin)."""
    x0, vx = -1.6, 5.0
    z0, vz = 0.35, 0.8
    return x0 + vx * t, 0.05, max(0.02, z0 + vz * t - 4.905 * t * t)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--to", default="127.0.0.1:41000", help="topspin's tracker address HOST:PORT")
    ap.add_argument("--count", type=int, default=200, help="observations to send")
    ap.add_argument("--rate", type=float, default=200.0, help="observations per second")
    args = ap.parse_args()
    host, port = args.to.rsplit(":", 1)
    sender = Sender(host, int(port))
    period_ns = int(round(1e9 / args.rate))
    start = time.monotonic_ns()
    for k in range(args.count):
        capture = start + k * period_ns
        x, y, z = _flight((k * period_ns * 1e-9) % 0.6)
        sender.send(capture, x, y, z, residual=0.001, cameras=3)
        delay = capture + period_ns - time.monotonic_ns()
        if delay > 0:
            time.sleep(delay * 1e-9)
    sender.close()
    print(f"sent {args.count} TTB1 observations to {args.to}")


if __name__ == "__main__":
    main()
