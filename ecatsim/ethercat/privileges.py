"""Drop privileges once the sockets are open: keep only CAP_NET_RAW (and CAP_NET_ADMIN
where a slave has EoE: the master may set its TAP device's address at any time);
optionally switch user.

Ref: capabilities(7), prctl(2) (PR_CAPBSET_DROP, PR_SET_KEEPCAPS), capset(2).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import pwd
import struct

from ecatsim.errors import UserError

CAP_NET_ADMIN = 12
CAP_NET_RAW = 13
CAP_LAST = 63
PR_CAPBSET_DROP = 24
PR_SET_KEEPCAPS = 8
_LINUX_CAPABILITY_VERSION_3 = 0x20080522


def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)


def _capset(keep: int) -> None:
    libc = _libc()
    header = ctypes.create_string_buffer(struct.pack("<Ii", _LINUX_CAPABILITY_VERSION_3, 0))
    lo, hi = keep & 0xFFFFFFFF, keep >> 32
    data = ctypes.create_string_buffer(struct.pack("<6I", lo, lo, 0, hi, hi, 0))
    if libc.capset(header, data) != 0:
        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err))


def drop_privileges(user: str | None, net_admin: bool = False) -> None:
    """Keep CAP_NET_RAW only (bounding, permitted, effective); switch to ``user`` if given.
    ``net_admin``: keep CAP_NET_ADMIN too (a slave has EoE: EoE Set IP Parameter sets
    the address of its TAP device). Ref: ETG.1000.6 §5.7.

    Without root there is nothing to drop (the daemon then already runs with what it was
    given, e.g. a file capability on the interpreter).
    """
    if os.geteuid() != 0:
        if user is not None:
            raise UserError("--user needs the daemon to be started as root")
        return
    libc = _libc()
    keep = {CAP_NET_RAW, CAP_NET_ADMIN} if net_admin else {CAP_NET_RAW}
    for cap in range(CAP_LAST + 1):
        if cap not in keep:
            libc.prctl(PR_CAPBSET_DROP, cap, 0, 0, 0)  # EINVAL for unknown caps: ignored
    if user is not None:
        try:
            pw = pwd.getpwnam(user)
        except KeyError as exc:
            raise UserError(f"--user {user}: no such user (create it or pick another)") from exc
        libc.prctl(PR_SET_KEEPCAPS, 1, 0, 0, 0)
        os.setgroups([])
        os.setgid(pw.pw_gid)
        os.setuid(pw.pw_uid)
    _capset(sum(1 << c for c in keep))
