"""ICMP echo ("ping") from Python, for namespaces without a ping program.

A raw ICMP socket (root) sends echo requests with this process's identifier and counts
the matching echo replies. Create it inside the namespace it should ping from
(tests/integration/netns.py ``in_netns``).
Ref: RFC 792 (echo, echo reply), RFC 1071 (checksum).
"""

from __future__ import annotations

import os
import select
import socket
import struct
import time

ECHO_REQUEST = 8
ECHO_REPLY = 0


def checksum(data: bytes) -> int:
    if len(data) % 2:
        data += b"\x00"
    s = sum(struct.unpack(f"!{len(data) // 2}H", data))
    s = (s >> 16) + (s & 0xFFFF)
    s += s >> 16
    return int(~s & 0xFFFF)


def echo_request(ident: int, seq: int, payload: bytes) -> bytes:
    hdr = struct.pack("!BBHHH", ECHO_REQUEST, 0, 0, ident, seq)
    return struct.pack("!BBHHH", ECHO_REQUEST, 0, checksum(hdr + payload), ident, seq) + payload


class Pinger:
    """An ICMP socket; :meth:`ping` sends ``count`` requests and counts the answers."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_ICMP)
        self.ident = os.getpid() & 0xFFFF
        self.seq = 0

    def ping(
        self, dst: str, count: int, size: int = 56, timeout: float = 3.0, interval: float = 0.2
    ) -> int:
        """Echo requests with ``size`` payload bytes to ``dst``, one per ``interval`` s
        (each waits up to ``timeout`` s for its reply); the number answered with the same
        payload."""
        answered = 0
        for _ in range(count):
            self.seq = (self.seq + 1) & 0xFFFF
            payload = bytes((self.seq + i) & 0xFF for i in range(size))
            self.sock.sendto(echo_request(self.ident, self.seq, payload), (dst, 0))
            sent = time.monotonic()
            deadline = sent + timeout
            while True:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                ready, _, _ = select.select([self.sock], [], [], left)
                if not ready:
                    break
                pkt = self.sock.recv(65535)
                ihl = (pkt[0] & 0x0F) * 4
                icmp = pkt[ihl:]
                if len(icmp) < 8:
                    continue
                kind, _, _, ident, seq = struct.unpack_from("!BBHHH", icmp)
                if kind == ECHO_REPLY and ident == self.ident and seq == self.seq:
                    if icmp[8:] == payload:
                        answered += 1
                    break
            rest = interval - (time.monotonic() - sent)
            if rest > 0:
                time.sleep(rest)
        return answered

    def close(self) -> None:
        self.sock.close()
