"""The link interface: bytes in and bytes out, nothing else.

A link delivers whole frames. For Ethernet links (raw socket, TAP, loopback) a frame
starts with the Ethernet header; for the UDP link it starts with the EtherCAT header.
"""

from __future__ import annotations

from typing import Protocol


class Link(Protocol):
    """One port towards the master."""

    #: True if frames carry an Ethernet header (raw/TAP/loopback); False for UDP.
    ethernet: bool
    #: Host monotonic time (ns) the last received frame arrived, from the kernel's receive
    #: time stamp; 0 if the link has none (then the daemon takes the time it reads it).
    rx_ns: int

    def fileno(self) -> int:
        """A file descriptor that is readable when a frame is waiting (for select/poll)."""
        ...

    def recv_into(self, buf: bytearray) -> int:
        """Receive one frame into ``buf``. Return its length, or 0 if nothing usable
        was waiting (would block, own outgoing frame, not EtherCAT)."""
        ...

    def send(self, frame: memoryview) -> None:
        """Send one frame (the same buffer, patched in place)."""
        ...

    def close(self) -> None: ...
