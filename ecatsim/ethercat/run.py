"""``ecatsim run``: open the link, build the segment, serve until told to stop."""

from __future__ import annotations

import gc
import os
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import structlog

from ecatsim import compiled
from ecatsim.clock import MonotonicClock
from ecatsim.ctl.server import ControlSocket, default_path, run_dir
from ecatsim.device.drive import Drive
from ecatsim.device.trace import TraceWriter
from ecatsim.doors.from_config import build_doors
from ecatsim.errors import UserError
from ecatsim.ethercat import realtime
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.daemon import Daemon, OutPort
from ecatsim.ethercat.gcwatch import GcPauses
from ecatsim.ethercat.linklock import LinkLock, lock_link, lock_name
from ecatsim.ethercat.privileges import drop_privileges
from ecatsim.ethercat.segment import Segment
from ecatsim.ethercat.segment_file import (
    SegmentConfig,
    default_segment,
    load_segment,
    repeat_default,
)
from ecatsim.faults.engine import FaultEngine
from ecatsim.faults.spec import FaultSpecError
from ecatsim.link.base import Link
from ecatsim.link.errors import LinkError
from ecatsim.link.follow import CpuFollower
from ecatsim.link.raw import RawLink, has_carrier, iface_ipv4_addresses
from ecatsim.logqueue import LogQueue
from ecatsim.mfcio import trace as mfcio_trace
from ecatsim.mfcio.block import MfcioBlock

log = structlog.get_logger("ecatsim")


@dataclass(frozen=True, slots=True)
class RunOptions:
    """Options of ``ecatsim run``."""

    iface: str | None = None
    tap: str | None = None
    udp: str | None = None
    config: Path | None = None
    slaves: int | None = None
    trace_frames: bool = False
    allow_ip_iface: bool = False
    busy_poll: bool = False
    cpu: int | None = None
    rt_priority: int | None = None
    no_rt: bool = False
    follow_master_cpu: bool = True
    #: real-time: hold a CPU latency request of 0 us while serving (decision K12)
    hold_cpu_latency: bool = True
    trace: Path | None = None
    ctl: Path | None = None
    user: str | None = None
    #: the segment from an ENI (ETG.2100), with ESIs from this folder
    eni: Path | None = None
    esi_dir: Path | None = None
    #: port 1 of the last slave leaves on this interface (the segment file's out_iface)
    out_iface: str | None = None
    #: where the daemon holds its log lines while it serves (decision P37)
    logs: LogQueue | None = None


def segment_config(opts: RunOptions) -> SegmentConfig:
    """The segment from --config, --slaves or the embedded default."""
    if opts.config is not None and opts.slaves is not None:
        raise UserError("--config and --slaves exclude each other: put 'count: N' in the YAML")
    if opts.eni is not None:
        if opts.config is not None or opts.slaves is not None:
            raise UserError("--eni lists the slaves: leave out --config and --slaves")
        from ecatsim.ethercat.segment_file import parse_segment

        data = {"eni": str(opts.eni.resolve())}
        if opts.esi_dir is not None:
            data["esi_dir"] = str(opts.esi_dir.resolve())
        return parse_segment(data, f"--eni {opts.eni}")
    if opts.esi_dir is not None:
        raise UserError("--esi-dir goes with --eni (the ESIs of the ENI's slaves)")
    if opts.config is not None:
        return load_segment(opts.config)
    if opts.slaves is not None:
        return repeat_default(opts.slaves)
    return default_segment()


def udp_address(udp: str) -> tuple[str, int]:
    """``--udp HOST:PORT`` as (host, port); one line with the fix if it is not that."""
    host, sep, port = udp.rpartition(":")
    if not sep or not port.isdigit():
        raise UserError(f"--udp {udp}: expected HOST:PORT, e.g. 127.0.0.1:34980")
    return host or "0.0.0.0", int(port)


def take_link(opts: RunOptions) -> LinkLock | None:
    """The lock of the one link this daemon will serve (decision O1): refused with the
    PID of the daemon serving it already."""
    chosen = [x for x in (opts.iface, opts.tap, opts.udp) if x]
    if len(chosen) != 1:
        raise UserError("give exactly one of --iface IFACE, --tap NAME or --udp HOST:PORT")
    port = udp_address(opts.udp)[1] if opts.udp else None
    return lock_link(run_dir(), opts.iface, opts.tap, port)


def open_link(opts: RunOptions) -> Link:
    """Open exactly one of --iface, --tap, --udp. Errors are one line with the fix."""
    chosen = [x for x in (opts.iface, opts.tap, opts.udp) if x]
    if len(chosen) != 1:
        raise UserError("give exactly one of --iface IFACE, --tap NAME or --udp HOST:PORT")
    try:
        if opts.iface:
            addrs = iface_ipv4_addresses(opts.iface)
            if addrs and not opts.allow_ip_iface:
                raise UserError(
                    f"interface {opts.iface} has IPv4 address {addrs[0]}: refusing to take over a "
                    "configured NIC; use a dedicated interface or pass --allow-ip-iface"
                )
            return RawLink(opts.iface)
        if opts.tap:
            from ecatsim.link.tap import TapLink

            return TapLink(opts.tap)
        from ecatsim.link.udp import UdpLink

        host, port = udp_address(opts.udp or "")
        return UdpLink(host, port)
    except LinkError as exc:
        raise UserError(str(exc)) from exc


def open_out(opts: RunOptions, cfg: SegmentConfig) -> OutPort | None:
    """The out interface (``--out-iface`` or the segment file's ``out_iface:``), raw."""
    name = opts.out_iface or cfg.out_iface
    if name is None:
        return None
    if name in (opts.iface, opts.tap):
        raise UserError(f"--out-iface {name}: must differ from the daemon's own interface")
    try:
        if iface_ipv4_addresses(name) and not opts.allow_ip_iface:
            raise UserError(
                f"interface {name} has IPv4 address: refusing to take over a configured NIC "
                "for --out-iface; use a dedicated interface or pass --allow-ip-iface"
            )
        return OutPort(RawLink(name), partial(has_carrier, name))
    except LinkError as exc:
        raise UserError(f"--out-iface {name}: {exc}") from exc


def attach_trace(segment: Segment, path: Path) -> TraceWriter:
    """Give every drive of the segment a tracer writing into one CSV."""
    writer = TraceWriter(path)
    for pos, fw in enumerate(segment.firmware):
        device = getattr(fw, "device", None)
        if isinstance(device, Drive):
            device.tracer = lambda now, row, pos=pos: writer.row(now, pos, row)
    return writer


def arm_faults(cfg: SegmentConfig, segment: Segment) -> FaultEngine:
    """The fault engine with the segment file's ``faults:`` armed (from now)."""
    engine = FaultEngine(segment)
    now = segment.clock.now_ns()
    for i, spec in enumerate(cfg.faults):
        try:
            engine.add(spec, now)
        except FaultSpecError as exc:
            raise UserError(f"{cfg.source}: faults[{i}]: {exc}") from None
    return engine


def follow_master(opts: RunOptions, link: Link) -> CpuFollower | None:
    """The CPU follower (decision K5) where it applies: a raw interface, the daemon
    real-time and not pinned by --cpu, --no-follow-master-cpu not given."""
    if not opts.follow_master_cpu or opts.cpu is not None or not isinstance(link, RawLink):
        return None
    try:
        return CpuFollower(link.iface)
    except OSError as exc:
        log.warning("follow_master_cpu_unavailable", reason=exc.strerror)
        return None


def run_daemon(opts: RunOptions) -> None:
    """Take the locks of the link and of the out interface (before anything is written:
    EEPROM, trace), then serve."""
    locks = [take_link(opts)]
    try:
        cfg = segment_config(opts)
        out_name = opts.out_iface or cfg.out_iface
        if out_name is not None:  # a link too: one daemon sends and receives on it (O1)
            locks.append(
                LinkLock(run_dir() / lock_name("iface", out_name), f"--out-iface {out_name}")
            )
        serve(opts, cfg)
    finally:
        for lock in reversed(locks):
            if lock is not None:
                lock.close()


def serve(opts: RunOptions, cfg: SegmentConfig) -> None:
    """Build everything, log ``ready``, serve until SIGINT/SIGTERM."""
    priority = realtime.choose_priority(opts.rt_priority, opts.no_rt, opts.busy_poll, opts.cpu)
    clock = MonotonicClock()
    out_name = opts.out_iface or cfg.out_iface
    segment = build_segment(cfg, clock, out=out_name is not None)
    tracer = attach_trace(segment, opts.trace) if opts.trace is not None else None
    blocks = [(i, fw) for i, fw in enumerate(segment.firmware) if isinstance(fw, MfcioBlock)]
    mfcio_tracer = mfcio_trace.attach(blocks, opts.trace) if opts.trace is not None else None
    link = open_link(opts)
    out = open_out(opts, cfg)
    if opts.cpu is not None:
        try:
            os.sched_setaffinity(0, {opts.cpu})
        except OSError as exc:
            raise UserError(f"--cpu {opts.cpu}: cannot pin ({exc.strerror})") from exc
    faults = arm_faults(cfg, segment)
    doors = build_doors(cfg, segment)
    where = opts.iface or opts.tap or opts.udp or "ecatsim"
    ctl = ControlSocket(opts.ctl or default_path(where), segment, faults, doors)
    daemon = Daemon(
        link,
        segment,
        busy_poll=opts.busy_poll,
        trace_frames=opts.trace_frames,
        ctl=ctl,
        faults=faults,
        doors=doors,
        out=out,
        logs=opts.logs,
    )
    # Everything built so far lives for the whole run: keep it out of the cyclic garbage
    # collector so a full collection cannot stall a reply by milliseconds.
    gc.collect()
    gc.freeze()
    latency_fd: int | None = None
    if realtime.apply(priority, explicit=opts.rt_priority is not None):
        daemon.follower = follow_master(opts, link)
        if opts.hold_cpu_latency:
            latency_fd = realtime.hold_cpu_latency()
    compiled.say_if_pure()  # one warning line where the pure-Python core serves
    # sockets and files are open: keep CAP_NET_RAW only (and CAP_NET_ADMIN for EoE)
    drop_privileges(opts.user, net_admin=any(sc.eoe is not None for sc in cfg.slaves))
    daemon.install_signal_handlers()
    log.info(
        "ready",
        link=where,
        out_link=out_name,
        slaves=len(segment.escs),
        config=cfg.source,
        mode="busy-poll" if opts.busy_poll else "blocking",
        ctl=str(ctl.path),
        doors=sorted(doors.doors) if doors is not None else [],
    )
    pauses = GcPauses()
    try:
        with pauses:
            daemon.run()
    finally:
        if latency_fd is not None:
            os.close(latency_fd)  # the CPUs may idle again
        daemon.close()
        ctl.close()
        if doors is not None:
            doors.close()
        if tracer is not None:
            tracer.close()
        if mfcio_tracer is not None:
            mfcio_tracer.close()
        log.info(
            "stopped",
            frames=segment.frames,
            replies=daemon.replies,
            compiled_replies=daemon.compiled_replies,
            bad_frames=segment.bad_frames,
            sync0_pulses=segment.schedule.sync0_ticks,
            sync0_max_late_us=segment.schedule.sync0_late_ns // 1000,
            sync0_deferred=segment.schedule.sync0_deferred,
            sync0_merged=segment.schedule.sync0_merged,
            failures=daemon.failures,
            cpu_moves=daemon.follower.moves if daemon.follower is not None else 0,
            cpu_follow_pauses=daemon.follower.pauses if daemon.follower is not None else 0,
            gc_collections=pauses.count,
            gc_max_us=pauses.max_ns // 1000,
            **daemon.reply_times(),
        )
