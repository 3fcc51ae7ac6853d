"""Command line: ``ecatsim run``, ``ecatsim eeprom ...``, ``ecatsim --version``.

User-caused errors are one line (``ecatsim: error: ...``) and exit status 2; ``--debug``
adds the traceback.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import click

from ecatsim import __version__
from ecatsim.bench.cli import bench
from ecatsim.errors import UserError
from ecatsim.lin.cli import lin
from ecatsim.logsetup import configure_logging, log_format_option
from ecatsim.tmcl.cli import tmcl


def _print_version(ctx: click.Context, value: bool) -> None:
    """``ecatsim --version``: the version, then ``core: compiled`` or ``core: pure-python
    (reason)`` (decision P2)."""
    if not value or ctx.resilient_parsing:
        return
    from ecatsim.compiled import core_line

    click.echo(f"ecatsim, version {__version__}")
    click.echo(core_line())
    ctx.exit()


class _Ctx:
    debug = False


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option(
    "--version",
    is_flag=True,
    expose_value=False,
    is_eager=True,
    callback=lambda ctx, _p, value: _print_version(ctx, value),
    help="Show the version and which core runs (compiled or pure-python), then exit.",
)
@click.option("--debug", is_flag=True, help="Show tracebacks for errors.")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """ecatsim: emulated Trinamic motion devices (TMC8460 ESC with MFCIO, TMC8670 CoE drive,
    TMCM-1311 over TMCL, TMC211 on LIN)."""
    ctx.obj = _Ctx()
    ctx.obj.debug = debug


@cli.command()
@click.option("--iface", help="Serve a network interface through a raw AF_PACKET socket.")
@click.option(
    "--out-iface",
    "out_iface",
    help="Port 1 of the last slave leaves on this interface: the next daemon's --iface, "
    "more slaves, or the master's second NIC (cable redundancy).",
)
@click.option("--tap", "tap", help="Create and serve a TAP device with this name.")
@click.option("--udp", "udp", help="Serve EtherCAT over UDP on HOST:PORT (port 34980 = 0x88A4).")
@click.option("--config", "config_path", type=click.Path(path_type=Path), help="Segment YAML.")
@click.option("--slaves", type=int, help="Repeat the default device N times.")
@click.option("--eni", type=click.Path(path_type=Path), help="The segment an ENI (ETG.2100) lists.")
@click.option(
    "--esi-dir", "esi_dir", type=click.Path(path_type=Path), help="With --eni: ESIs of its slaves."
)
@log_format_option
@click.option("--trace-frames", is_flag=True, help="Log every frame (slow; for debugging).")
@click.option("--allow-ip-iface", is_flag=True, help="Allow an interface with an IPv4 address.")
@click.option("--busy-poll", is_flag=True, help="Spin instead of blocking (lowest latency).")
@click.option("--cpu", type=int, help="Pin the daemon to this CPU.")
@click.option(
    "--rt-priority",
    type=click.IntRange(1, 99),
    help="SCHED_FIFO priority (default: 20 where allowed, blocking mode only; needs root "
    "or CAP_SYS_NICE).",
)
@click.option("--no-rt", is_flag=True, help="Keep the ordinary scheduler (no SCHED_FIFO).")
@click.option(
    "--follow-master-cpu/--no-follow-master-cpu",
    default=True,
    show_default=True,
    help="Real-time on a raw interface without --cpu: run on the CPU the master's frames "
    "come from, so the reply is there before the master first looks for it.",
)
@click.option(
    "--hold-cpu-latency/--no-hold-cpu-latency",
    default=True,
    show_default=True,
    help="Real-time: keep every CPU out of its idle states while serving (a CPU latency "
    "request of 0 us on /dev/cpu_dma_latency, as cyclictest does), so a frame never waits "
    "for a CPU to wake up.",
)
@click.option("--trace", "trace", type=click.Path(path_type=Path), help="Per-cycle drive CSV.")
@click.option(
    "--ctl",
    "ctl",
    type=click.Path(path_type=Path),
    help="Control socket path (0600; default: /run/ecatsim/LINK.sock).",
)
@click.option("--user", "user", help="Started as root: switch to this user after opening.")
@click.pass_obj
def run(
    obj: _Ctx,
    iface: str | None,
    out_iface: str | None,
    tap: str | None,
    udp: str | None,
    config_path: Path | None,
    slaves: int | None,
    eni: Path | None,
    esi_dir: Path | None,
    log_format: str,
    trace_frames: bool,
    allow_ip_iface: bool,
    busy_poll: bool,
    cpu: int | None,
    rt_priority: int | None,
    no_rt: bool,
    follow_master_cpu: bool,
    hold_cpu_latency: bool,
    trace: Path | None,
    ctl: Path | None,
    user: str | None,
) -> None:
    """Emulate the segment on an interface until SIGINT/SIGTERM."""
    from ecatsim.ethercat.run import RunOptions, run_daemon

    logs = configure_logging(log_format, logging.DEBUG if trace_frames else logging.INFO)
    opts = RunOptions(
        logs=logs,
        iface=iface,
        tap=tap,
        udp=udp,
        config=config_path,
        slaves=slaves,
        trace_frames=trace_frames,
        allow_ip_iface=allow_ip_iface,
        busy_poll=busy_poll,
        cpu=cpu,
        rt_priority=rt_priority,
        no_rt=no_rt,
        follow_master_cpu=follow_master_cpu,
        hold_cpu_latency=hold_cpu_latency,
        trace=trace,
        ctl=ctl,
        user=user,
        eni=eni,
        esi_dir=esi_dir,
        out_iface=out_iface,
    )
    run_daemon(opts)


@cli.command("ctl")
@click.option("--socket", "sock", type=click.Path(path_type=Path), help="The daemon's --ctl path.")
@click.option("--link", "link", help="Or: the daemon's --iface/--tap/--udp (default socket).")
@click.argument(
    "command",
    type=click.Choice(
        [
            "status",
            "inject",
            "clear",
            "fault",
            "peek",
            "poke",
            "od",
            "al_refuse",
            "al_fall",
            "mbx_drop",
            "wire",
            "link",
            "door",
            "mfcio",
            "pd",
        ]
    ),
)
@click.option("--json", "as_json", is_flag=True, help="Print the daemon's answer as JSON.")
@click.argument("args", nargs=-1)
def ctl_cmd(
    sock: Path | None, link: str | None, as_json: bool, command: str, args: tuple[str, ...]
) -> None:
    """Talk to a running daemon (found by itself when exactly one runs).

    \b
    status                          AL state/code, DL status, error counters, active faults
    inject KIND [key=value ...]     any fault, keys as in the segment YAML's faults: list,
                                    e.g. inject wkc value=-1 count=3 after_frames=100
                                         inject link_down slave=1 port=1 after_s=2 for_s=1
                                         inject sdo_abort index=0x6060 code=0x06010000
    clear [ID]                      remove one fault (ID from inject/status), or all
    fault SLAVE KIND | clear SLAVE KIND   a drive fault, held until cleared
    al_refuse SLAVE CODE | al_fall SLAVE CODE | mbx_drop SLAVE N | wire KIND N [VALUE]
    link SLAVE PORT up|down | peek SLAVE ADDR LEN | poke SLAVE ADDR HEX | od SLAVE INDEX SUB [V]
    door tmcl|lin COMMAND [ARGS]    a request for a TMCL or LIN front door (door tmcl help)
    mfcio SLAVE [status|pins|set gpioN 0|1|open|set nes 0|1|read REG|write REG V]
                                    a TMC8460's MFCIO block (MFC CTRL SPI for read/write)
    pd SLAVE [ENTRY [VALUE]]        process data: every mapped entry with its value; one
                                    entry (0xIIII:SS or name); or set an input to VALUE
    """
    import json

    from ecatsim.ctl.server import default_path, find_socket, parse_value, request
    from ecatsim.ctl.table import format_status

    def num(v: str) -> int:
        return int(v, 0)

    try:
        if command == "status":
            req: dict[str, object] = {"cmd": "status"}
        elif command == "inject":
            fault: dict[str, object] = {"kind": args[0]}
            for kv in args[1:]:
                key, sep, value = kv.partition("=")
                if not sep:
                    raise ValueError(kv)
                fault[key] = parse_value(value)
            req = {"cmd": "inject", "fault": fault}
        elif command == "clear" and len(args) == 2:  # clear SLAVE KIND: a drive fault
            req = {"cmd": "fault", "slave": num(args[0]), "kind": args[1], "active": False}
        elif command == "clear":
            req = {"cmd": "clear", "id": num(args[0]) if args else None}
        elif command == "fault":
            req = {"cmd": "fault", "slave": num(args[0]), "kind": args[1], "active": True}
        elif command == "peek":
            req = {"cmd": "peek", "slave": num(args[0]), "addr": num(args[1]), "len": num(args[2])}
        elif command in ("al_refuse", "al_fall"):
            req = {"cmd": command, "slave": num(args[0]), "code": num(args[1])}
        elif command == "wire":
            req = {"cmd": "wire", "kind": args[0], "count": num(args[1])}
            if len(args) > 2:
                req["value"] = num(args[2])
        elif command == "link":
            req = {"cmd": "link", "slave": num(args[0]), "port": num(args[1])}
            req["up"] = args[2] == "up"
        elif command == "mbx_drop":
            req = {"cmd": command, "slave": num(args[0]), "count": num(args[1])}
        elif command == "mfcio":
            req = {
                "cmd": "mfcio",
                "slave": num(args[0]),
                "op": args[1] if len(args) > 1 else "status",
                "args": list(args[2:]),
            }
        elif command == "door":
            req = {"cmd": "door", "door": args[0], "command": args[1], "args": list(args[2:])}
        elif command == "pd":
            req = {"cmd": "pd", "slave": num(args[0])}
            if len(args) > 1:
                req["entry"] = args[1]
            if len(args) > 2:
                req["value"] = parse_value(args[2])
            if len(args) > 3:
                raise ValueError(args[3])
        elif command == "poke":
            req = {"cmd": "poke", "slave": num(args[0]), "addr": num(args[1]), "data": args[2]}
        else:
            req = {"cmd": "od", "slave": num(args[0]), "index": num(args[1]), "sub": num(args[2])}
            if len(args) > 3:
                req["value"] = num(args[3])
    except (IndexError, ValueError) as exc:
        raise UserError(f"ctl {command}: bad arguments {' '.join(args)!r} (see --help)") from exc
    if sock is None:
        door = str(req["door"]) if command == "door" else None
        sock = default_path(link) if link is not None else find_socket(door=door)
    reply = request(sock, req)
    if as_json:
        click.echo(json.dumps(reply, indent=2))
    elif not reply.get("ok"):
        click.echo(f"ecatsim: error: ctl {command}: {reply.get('error')}", err=True)
    elif command == "status":
        click.echo(format_status(reply))
    elif command == "pd":
        from ecatsim.slave.pd import format_entries

        click.echo(format_entries(reply.get("entries", [reply])))
    elif set(reply) == {"ok", "commands"}:  # a door's help: one command a line
        cmds = reply["commands"]
        lines = [f"{k}: {v}" for k, v in cmds.items()] if isinstance(cmds, dict) else cmds
        click.echo("\n".join(str(c) for c in lines))
    else:
        click.echo(json.dumps({k: v for k, v in reply.items() if k != "ok"}, indent=2))
    if not reply.get("ok"):
        raise SystemExit(1)


@cli.command("plot")
@click.argument("csv_path", metavar="TRACE.csv", type=click.Path(path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(path_type=Path))
@click.option("--slave", type=int, help="Which slave (default: the first in the file).")
def plot_cmd(csv_path: Path, output: Path, slave: int | None) -> None:
    """Plot a --trace CSV: position, velocity, torque, set point over actual; or its
    FILE.mfcio.csv: a TMC8460's steps, motor position and encoder."""
    from ecatsim.device.trace import plot, trace_columns
    from ecatsim.mfcio import trace as mfcio_trace

    if trace_columns(csv_path)[: len(mfcio_trace.COLUMNS)] == mfcio_trace.COLUMNS:
        from ecatsim.mfcio.plot import plot_mfcio

        plot_mfcio(csv_path, output, slave)
    else:
        plot(csv_path, output, slave)
    click.echo(f"{output}: written")


@cli.group()
def eeprom() -> None:
    """SII EEPROM images."""


@eeprom.command("show")
@click.argument("image", type=click.Path(path_type=Path))
def eeprom_show(image: Path) -> None:
    """Decode an SII image: header, CRC, strings and categories."""
    from ecatsim.sii.image import SiiError, format_image, parse_image

    try:
        data = image.read_bytes()
    except OSError as exc:
        raise UserError(f"{image}: cannot read ({exc.strerror})") from exc
    try:
        click.echo(format_image(parse_image(data)))
    except SiiError as exc:
        from ecatsim.sii.crc import crc8

        crc = ""
        if len(data) >= 16 and (want := crc8(data[0:14])) != data[14]:
            crc = f"; and the header checksum (word 7) is 0x{data[14]:02X}, not 0x{want:02X}"
        raise UserError(f"{image}: not an SII EEPROM image: {exc}{crc}") from exc


def main() -> None:
    """Entry point: run the CLI, turning user errors into one line."""
    debug = "--debug" in sys.argv
    try:
        cli.main(standalone_mode=False)
    except click.exceptions.Abort:
        sys.exit(130)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except UserError as exc:
        if debug:
            raise
        click.echo(f"ecatsim: error: {exc}", err=True)
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)


@eeprom.command("build")
@click.argument("esi_path", metavar="ESI.xml", type=click.Path(path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(path_type=Path))
@click.option("--product", type=str, help="ProductCode of the device (when the ESI has several).")
@click.option("--revision", type=str, help="RevisionNo of the device.")
@click.option("--serial", type=int, default=0, show_default=True, help="Serial number (SII 0x0E).")
@click.option("--alias", type=int, default=None, help="Station alias (SII word 4).")
def eeprom_build(
    esi_path: Path,
    output: Path,
    product: str | None,
    revision: str | None,
    serial: int,
    alias: int | None,
) -> None:
    """Build an SII image from any ESI file (written atomically)."""
    from ecatsim.device.esi import EsiError, read_esi
    from ecatsim.files import write_output
    from ecatsim.sii.image import SiiError, build_image

    def num(option: str, v: str | None) -> int | None:
        if v is None:
            return None
        try:
            return int(v.replace("#x", "0x"), 0)
        except ValueError:
            e = "8670, 0x21DE or #x21DE" if option == "--product" else "65536 or 0x10000"
            raise UserError(
                f"{option} {v}: not a number; give it as in the ESI, e.g. {e}"
            ) from None

    try:
        desc = read_esi(esi_path, num("--product", product), num("--revision", revision))
        image = build_image(desc, serial=serial, alias=alias)
    except (EsiError, SiiError, ValueError) as exc:
        raise UserError(str(exc)) from exc
    write_output(output, image)
    click.echo(f"{output}: {len(image)} bytes for {desc.name} ({desc.identity.product_code:#x})")


@cli.group()
def esi() -> None:
    """ESI (ETG.2000) files."""


@esi.command("export")
@click.option("-o", "--output", required=True, type=click.Path(path_type=Path))
@click.option(
    "--device",
    type=click.Choice(["tmc8670", "tmc8460"]),
    default="tmc8670",
    show_default=True,
    help="Which packaged device: the TMC8670 drive or the TMC8460 MFCIO slave.",
)
@click.option(
    "--description", type=click.Path(path_type=Path), help="Or: a device description YAML."
)
@click.option("--eoe", is_flag=True, help="Declare EoE, as for a slave configured with 'eoe:'.")
def esi_export(output: Path, device: str, description: Path | None, eoe: bool) -> None:
    """Write the ESI XML of an emulated device (written atomically); a TMC8460 MFCIO
    configuration (SII category 1) is decoded register by register in comments."""
    from ecatsim.device.description import (
        DescriptionError,
        default_description,
        load_description,
        with_protocol,
    )
    from ecatsim.device.esi import export_esi
    from ecatsim.files import write_output
    from ecatsim.slave.od_build import build_od

    try:
        if description is not None:
            try:
                desc = load_description(description)
            except DescriptionError as exc:
                raise UserError(f"--description {exc}") from exc
        else:
            desc = default_description(f"{device}.yaml")
        od = (
            build_od(desc, description.parent if description else None)
            if "coe" in desc.mailbox.protocols
            else None
        )
    except DescriptionError as exc:
        raise UserError(str(exc)) from exc
    if eoe:
        desc = with_protocol(desc, "eoe")
    write_output(output, export_esi(desc, od))
    click.echo(f"{output}: ESI of {desc.name}")


@esi.command("check")
@click.argument("files", nargs=-1, type=click.Path(path_type=Path))
@click.option("--esi-dir", "esi_dir", type=click.Path(path_type=Path), help="Every *.xml here too.")
def esi_check(files: tuple[Path, ...], esi_dir: Path | None) -> None:
    """Build every device of every ESI in process and bring it to OP through the loopback
    link with a minimal master: one line per device (ok, or what failed)."""
    from ecatsim.generic.check import check_files

    paths = list(files) + (sorted(esi_dir.glob("*.xml")) if esi_dir is not None else [])
    if not paths:
        raise UserError("esi check: give ESI files or --esi-dir DIR")
    failed = 0
    for line, ok in check_files(paths):
        click.echo(line)
        failed += not ok
    if failed:
        raise SystemExit(1)


@cli.group()
def eni() -> None:
    """ENI (ETG.2100) files."""


@eni.command("show")
@click.argument("eni_path", metavar="ENI.xml", type=click.Path(path_type=Path))
@click.option("--esi-dir", "esi_dir", type=click.Path(path_type=Path), help="ESIs of its slaves.")
def eni_show(eni_path: Path, esi_dir: Path | None) -> None:
    """List the ENI's slaves and the model each one gets."""
    from ecatsim.ethercat.eni import format_slaves, load_eni

    click.echo(format_slaves(load_eni(eni_path, esi_dir)))


cli.add_command(bench)
cli.add_command(lin)
cli.add_command(tmcl)
