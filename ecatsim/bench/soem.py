"""SOEM C programs built from pysoem's source distribution: the bench's large-segment master
and the integration tests' C masters.

pysoem's sdist (the installed pysoem's version: the bench extra, pinned in
requirements-test.lock) carries SOEM's C sources and its ``test/linux`` samples (red_test,
simple_test, eoe_test ...). :func:`soem_tree` fetches it once with the package registry's
ordinary client (``pip download``) and unpacks it; :func:`build_program` compiles SOEM with
a program's own C files, :func:`build_sample` one of SOEM's samples, each with optional
build-time substitutions of constants in the build copy (the fetched sources stay as
fetched). :func:`red_test` is SOEM's DC sample sized for large segments (``ecatsim bench
--bringup N --master soem``). Everything is cached under the venv (``<venv>/soem-build``,
or ``ECATSIM_SOEM_CACHE``), keyed by the sources and the substitutions, so each program
builds once; a file lock keeps parallel processes from building the same thing twice.

Ref: docs/performance.md "How to measure"; SOEM ethercatmain.h (EC_MAXSLAVE).
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import tarfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

from ecatsim.errors import UserError

#: SOEM's library sources inside the sdist's ``soem`` directory
LIB_DIRS = ("soem", "osal/linux", "oshw/linux")
INCLUDE_DIRS = ("soem", "osal", "osal/linux", "oshw/linux")
DOWNLOAD_TIMEOUT = 600
BUILD_TIMEOUT = 300

#: (file name, text found, text put in its place) applied to the build copy
Patch = tuple[str, str, str]

#: SOEM's frame timeout as shipped (``EC_TIMEOUTRET`` in ethercattype.h), in microseconds
STOCK_TIMEOUT_US = 2000

#: red_test sized for large segments: SOEM's slave table (entry 0 is the master's, so one
#: fewer slaves), the sample's IO map, and the frames SOEM keeps in flight (one per
#: process-data frame of a cycle plus the acyclic ones: 1023 drives of 29 bytes are 21 LRWs)
RED_MAXSLAVE = 1024
RED_IOMAP = 65536
RED_MAXBUF = 64
#: red_test's main loop prints every 20 ms while the cycle thread runs
RED_LOOP_US = 20_000


def pysoem_version() -> str:
    """The installed pysoem's version (its sdist carries the SOEM that is built)."""
    try:
        return metadata.version("pysoem")
    except metadata.PackageNotFoundError:
        raise UserError("the SOEM master needs pysoem: pip install 'ecatsim[bench]'") from None


def cache_root() -> Path:
    """Where downloads and builds are kept: in the venv (or ``ECATSIM_SOEM_CACHE``)."""
    override = os.environ.get("ECATSIM_SOEM_CACHE")
    return Path(override) if override else Path(sys.prefix) / "soem-build"


@contextmanager
def _locked(path: Path) -> Iterator[None]:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def soem_tree() -> Path:
    """The unpacked ``soem`` directory of pysoem's sdist (downloaded on first use).

    Only pysoem itself is taken as source (``--no-binary pysoem``): pip prepares the
    sdist's metadata in a build environment, and with ``--no-binary :all:`` it would
    compile that environment's Cython from source too, for many minutes."""
    version = pysoem_version()
    base = cache_root() / f"pysoem-{version}"
    tree = base / "src" / f"pysoem-{version}" / "soem"
    if (tree / "soem" / "ethercat.h").exists():
        return tree
    with _locked(base / ".lock"):
        if (tree / "soem" / "ethercat.h").exists():
            return tree
        dl = base / "download"
        dl.mkdir(parents=True, exist_ok=True)
        sdist = dl / f"pysoem-{version}.tar.gz"
        if not sdist.exists():
            r = subprocess.run(
                [sys.executable, "-m", "pip", "download", f"pysoem=={version}",
                 "--no-binary", "pysoem", "--no-deps", "-d", str(dl)],
                capture_output=True, text=True, timeout=DOWNLOAD_TIMEOUT, check=False,
            )  # fmt: skip
            if r.returncode != 0 or not sdist.exists():
                last = (r.stderr.strip().splitlines() or ["no output"])[-1]
                raise UserError(
                    f"the SOEM sources: 'pip download pysoem=={version} --no-binary pysoem' "
                    f"failed ({last}): check the network or pip's index"
                )
        tmp = base / "src.tmp"
        shutil.rmtree(tmp, ignore_errors=True)
        with tarfile.open(sdist) as tf:
            tf.extractall(tmp, filter="data")
        shutil.rmtree(base / "src", ignore_errors=True)
        tmp.rename(base / "src")
    return tree


#: pysoem's SOEM adds two fields (DCtO, DCl) to the master context but not to the
#: positional initializer of the global context the classic ``ec_*`` API (EC_VER1, which
#: SOEM's samples use) relies on; the build copy gets their zero values
_CONTEXT_FIX = (
    "    &EcatError,         // .ecaterror     =\n",
    "    0, 0,               // .DCtO, .DCl\n",
)


def _patched(src: Path, patches: Sequence[Patch]) -> str:
    """``src``'s text with the substitutions meant for its file name (each must match)."""
    text = src.read_text(errors="replace")
    for name, old, new in patches:
        if name == src.name:
            if old not in text:
                raise RuntimeError(f"{src.name} of pysoem's SOEM has no {old!r} to substitute")
            text = text.replace(old, new)
    return text


def _library(tree: Path, into: Path, patches: Sequence[Patch]) -> list[Path]:
    """SOEM's library sources and headers, copied into ``into`` with the context
    initializer fixed and ``patches`` applied; the C files."""
    fix: list[Patch] = []
    if "DCtO" in (tree / "soem" / "ethercatmain.h").read_text():
        anchor, extra = _CONTEXT_FIX
        if anchor in (tree / "soem" / "ethercatmain.c").read_text():
            fix = [("ethercatmain.c", anchor, anchor + extra)]
    out: list[Path] = []
    for d in sorted(set(LIB_DIRS) | set(INCLUDE_DIRS)):
        (into / d).mkdir(parents=True, exist_ok=True)
        for src in sorted((tree / d).glob("*.[ch]")):
            dst = into / d / src.name
            dst.write_text(_patched(src, [*fix, *patches]))
            if src.suffix == ".c" and d in LIB_DIRS:
                out.append(dst)
    return out


def build_program(name: str, sources: Sequence[Path], libs: Sequence[str] = (),
                  patches: Sequence[Patch] = ()) -> Path:  # fmt: skip
    """SOEM linked with ``sources`` into one executable (cached by content), ``patches``
    substituted in the build copy of SOEM and of ``sources``."""
    cc = shutil.which("cc")
    if cc is None:
        raise UserError("building the SOEM master needs a C compiler ('cc'): install one")
    tree = soem_tree()
    lib = sorted(p for d in (*LIB_DIRS, *INCLUDE_DIRS) for p in (tree / d).glob("*.[ch]"))
    digest = hashlib.sha256(repr((tuple(libs), tuple(patches))).encode())
    for p in (*lib, *sources):
        digest.update(p.name.encode() + p.read_bytes())
    out = cache_root() / f"pysoem-{pysoem_version()}" / "bin" / f"{name}-{digest.hexdigest()[:12]}"
    if out.exists():
        return out
    with _locked(out.parent / ".lock"):
        if out.exists():
            return out
        tmp = out.with_suffix(".tmp")
        work = out.parent / f"{out.name}.src"
        shutil.rmtree(work, ignore_errors=True)
        lib_copy = _library(tree, work, patches)
        own = []
        for i, src in enumerate(sources):
            dst = work / "program" / str(i) / src.name
            dst.parent.mkdir(parents=True, exist_ok=True)
            dst.write_text(_patched(src, patches))
            own.append(dst)
        cmd = [
            cc, "-O2", "-w", "-pthread", "-DEC_VER1",
            *(f"-I{work / d}" for d in INCLUDE_DIRS),
            *(str(p) for p in (*lib_copy, *own)),
            "-o", str(tmp), "-lrt", *libs,
        ]  # fmt: skip
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=BUILD_TIMEOUT, check=False)
        shutil.rmtree(work, ignore_errors=True)
        if r.returncode != 0:
            raise RuntimeError(f"building {name} failed: {r.stderr[-1500:]}")
        tmp.rename(out)
    return out


def build_sample(sample: str, patches: Sequence[Patch] = (), libs: Sequence[str] = ()) -> Path:
    """One of SOEM's own samples (``test/linux/<sample>/<sample>.c``), e.g. red_test."""
    src = soem_tree() / "test" / "linux" / sample / f"{sample}.c"
    if not src.exists():
        raise FileNotFoundError(f"pysoem's SOEM has no sample {sample}")
    return build_program(sample, [src], libs, patches)


def red_test_patches(loops: int, overlap: bool, sync0_ns: int = 0) -> list[Patch]:
    """The constants of red_test and SOEM changed for a large segment: the slave table
    (:data:`RED_MAXSLAVE`), the frames in flight (:data:`RED_MAXBUF`), the IO map
    (:data:`RED_IOMAP`) and the main loop's count (``loops`` of 20 ms; the sample's own is
    5000, 100 s). With ``overlap`` the sample maps and exchanges with SOEM's overlap calls
    (ec_config_overlap, ec_send_overlap_processdata) instead of ec_config and
    ec_send_processdata. With ``sync0_ns`` every slave's SYNC0 is started at that period
    right after ec_configdc (SOEM's ec_dcsync0, as pysoem's ``dc_sync`` does; the sample
    itself starts none)."""
    patches: list[Patch] = [
        ("ethercatmain.h", "#define EC_MAXSLAVE       200", f"#define EC_MAXSLAVE {RED_MAXSLAVE}"),
        ("ethercattype.h", "#define EC_MAXBUF          16", f"#define EC_MAXBUF {RED_MAXBUF}"),
        ("red_test.c", "char IOmap[4096];", f"char IOmap[{RED_IOMAP}];"),
        ("red_test.c", "i <= 5000;", f"i <= {loops};"),
    ]  # fmt: skip
    patches += drive_patches()
    if overlap:
        patches += [
            ("red_test.c", "ec_config(FALSE, &IOmap)", "ec_config_overlap(FALSE, &IOmap)"),
            ("red_test.c", "ec_send_processdata()", "ec_send_overlap_processdata()"),
        ]
    if sync0_ns:
        start = f"for (int s = 1; s <= ec_slavecount; s++) ec_dcsync0(s, TRUE, {sync0_ns}, 0);"
        patches.append(("red_test.c", "ec_configdc();", "ec_configdc(); " + start))
    return patches


#: every drive in cyclic synchronous position (6060h = 8) by SDO, in SAFEOP after ec_configdc
_CSP = (
    "for (int s = 1; s <= ec_slavecount; s++) { int8 csp = 8; "
    "ec_SDOwrite(s, 0x6060, 0, FALSE, sizeof(csp), &csp, EC_TIMEOUTRXM); }"
)
#: the cycle thread, between receiving a cycle and sending the next (SOEM's receive copies
#: the LRW's reply over the outputs too, so another thread's writes would be lost): the
#: main loop's step (one per 20 ms) gives controlword 6, 7, then 15 (five steps each), the
#: target position kept at the actual one until enabled; only slaves that map a TMC8670's
#: PDOs (controlword and target position out, statusword, mode display, position in)
_ENABLE = (
    "if (drive_step > 0) { for (int s = 1; s <= ec_slavecount; s++) { if (ec_slave[s].Obytes "
    ">= 6 && ec_slave[s].Ibytes >= 7) { uint16 cw = drive_step <= 5 ? 6 : (drive_step <= 10 ? "
    "7 : 15); if (drive_step <= 10) memcpy(ec_slave[s].outputs + 2, ec_slave[s].inputs + 3, "
    "4); ec_slave[s].outputs[0] = cw & 0xFF; ec_slave[s].outputs[1] = cw >> 8; } } }\n"
)
#: after the main loop: the drives in Operation Enabled (statusword & 6Fh == 27h) and in csp
_REPORT = (
    "{ int en = 0, csp = 0; for (int s = 1; s <= ec_slavecount; s++) { if (ec_slave[s].Ibytes "
    ">= 3) { en += (ec_slave[s].inputs[0] & 0x6F) == 0x27; csp += ec_slave[s].inputs[2] == 8; } "
    '} printf("\\nEnabled drives %d csp %d\\n", en, csp); }\n'
)


def drive_patches() -> list[Patch]:
    """red_test runs the drives as the pysoem master does: csp by SDO after ec_configdc,
    then each enabled (CiA 402-2 Figure 5: controlword 6, 7, 15) holding its position, and
    a line ``Enabled drives N csp M`` after its main loop (:mod:`ecatsim.bench.redtest`
    reads it). The sample itself leaves the outputs at zero."""
    return [
        ("red_test.c", "ec_configdc();", "ec_configdc(); " + _CSP),
        ("red_test.c", "int dorun = 0;", "int dorun = 0; volatile int drive_step = 0;"),
        ("red_test.c", "osal_usleep(20000);", "drive_step = i; osal_usleep(20000);"),
        ("red_test.c", "ec_sync(ec_DCtime, cycletime, &toff);\n         }\n",
         "ec_sync(ec_DCtime, cycletime, &toff);\n         }\n         " + _ENABLE),
        ("red_test.c", "            dorun = 0;\n            inOP = FALSE;",
         "            " + _REPORT + "            dorun = 0;\n            inOP = FALSE;"),
    ]  # fmt: skip


def frame_timeout_patch(timeout_us: int) -> Patch:
    """SOEM's frame timeout (``EC_TIMEOUTRET``, :data:`STOCK_TIMEOUT_US` as shipped) set
    to ``timeout_us``: a master's own setting."""
    return ("ethercattype.h", f"#define EC_TIMEOUTRET      {STOCK_TIMEOUT_US}",
            f"#define EC_TIMEOUTRET      {timeout_us}")  # fmt: skip


def red_test(cycles: int, period_us: int, overlap: bool, sync0: bool = False,
             timeout_us: int = 0) -> Path:  # fmt: skip
    """SOEM's red_test built for a large segment (:func:`red_test_patches`), its main
    loop long enough for ``cycles`` cycles of ``period_us``; with ``sync0`` SYNC0 runs at
    the period; with ``timeout_us`` SOEM waits that long for a frame instead of its stock
    2 ms (:func:`frame_timeout_patch`)."""
    loops = max(1, -(-cycles * period_us // RED_LOOP_US))
    patches = red_test_patches(loops, overlap, period_us * 1000 if sync0 else 0)
    if timeout_us:
        patches.append(frame_timeout_patch(timeout_us))
    return build_sample("red_test", patches, libs=("-lm",))
