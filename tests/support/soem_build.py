"""SOEM C programs for the integration tests, built from pysoem's source distribution.

pysoem's sdist (the version pinned in requirements-test.lock) carries SOEM's C sources and
its ``test/linux`` samples (eoe_test, red_test, simple_test ...). :func:`soem_tree` fetches
it once with the package registry's ordinary client (``pip download``) and unpacks it;
:func:`build_program` compiles SOEM with a program's own C files, :func:`build_sample` one
of SOEM's samples. Everything is cached under the venv (``<venv>/soem-build``), keyed by
the sources, so each program builds once; a file lock keeps parallel test processes from
building the same thing twice.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tarfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: SOEM's library sources inside the sdist's ``soem`` directory
LIB_DIRS = ("soem", "osal/linux", "oshw/linux")
INCLUDE_DIRS = ("soem", "osal", "osal/linux", "oshw/linux")
DOWNLOAD_TIMEOUT = 600
BUILD_TIMEOUT = 300


def pysoem_version() -> str:
    """The pysoem version requirements-test.lock pins."""
    text = (ROOT / "requirements-test.lock").read_text()
    m = re.search(r"^pysoem==([0-9][^\s;#]*)", text, re.MULTILINE)
    if m is None:
        raise RuntimeError("requirements-test.lock pins no pysoem version")
    return m.group(1)


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
                raise RuntimeError(f"pip download pysoem=={version} failed: {r.stderr[-800:]}")
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


def _library(tree: Path, into: Path) -> list[Path]:
    """SOEM's library sources, copied into ``into`` with the context initializer fixed."""
    out: list[Path] = []
    for d in LIB_DIRS:
        (into / d).mkdir(parents=True, exist_ok=True)
        for src in sorted((tree / d).glob("*.c")):
            text = src.read_text(errors="replace")
            if (
                src.name == "ethercatmain.c"
                and "DCtO" in (tree / "soem" / "ethercatmain.h").read_text()
            ):
                anchor, extra = _CONTEXT_FIX
                if anchor in text and extra not in text:
                    text = text.replace(anchor, anchor + extra, 1)
            dst = into / d / src.name
            dst.write_text(text)
            out.append(dst)
    return out


def build_program(name: str, sources: Sequence[Path], libs: Sequence[str] = ()) -> Path:
    """SOEM linked with ``sources`` into one executable (cached by content)."""
    tree = soem_tree()
    lib = sorted(p for d in LIB_DIRS for p in (tree / d).glob("*.c"))
    digest = hashlib.sha256()
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
        lib_copy = _library(tree, work)
        cmd = [
            "gcc", "-O2", "-w", "-pthread", "-DEC_VER1",
            *(f"-I{tree / d}" for d in INCLUDE_DIRS),
            *(str(p) for p in (*lib_copy, *sources)),
            "-o", str(tmp), "-lrt", *libs,
        ]  # fmt: skip
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=BUILD_TIMEOUT, check=False)
        shutil.rmtree(work, ignore_errors=True)
        if r.returncode != 0:
            raise RuntimeError(f"building {name} failed: {r.stderr[-1500:]}")
        tmp.rename(out)
    return out


def build_sample(sample: str) -> Path:
    """One of SOEM's own samples (``test/linux/<sample>/<sample>.c``), e.g. red_test."""
    src = soem_tree() / "test" / "linux" / sample / f"{sample}.c"
    if not src.exists():
        raise FileNotFoundError(f"pysoem's SOEM has no sample {sample}")
    return build_program(sample, [src])


def eoe_bridge() -> Path:
    """This project's EoE bridge master (tests/support/eoe_bridge.c) on that SOEM."""
    return build_program("eoe_bridge", [Path(__file__).with_name("eoe_bridge.c")])
