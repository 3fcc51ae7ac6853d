"""Build of the compiled core (decision P2): modules compiled by Cython from the same
``.py`` files that run as the pure-Python core, typed by the ``.pxd`` files beside them.
The list of modules is ``CORE`` in ecatsim/compiled.py (read here as text: the build does
not import the package).

Every extension is optional: where Cython, a C compiler or the Python headers are missing,
``pip install`` goes on and the ``.py`` modules run (ecatsim --version says which).
"""

from __future__ import annotations

import ast
import hashlib
import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from setuptools import Extension

ROOT = Path(__file__).parent
#: -ffp-contract=off: no fused multiply-add, so the compiled core's floating-point results
#: are the pure-Python core's, bit for bit
CFLAGS = ["-O2", "-ffp-contract=off"]


def core_modules() -> list[str]:
    """``CORE`` from ecatsim/compiled.py, without importing it."""
    tree = ast.parse((ROOT / "ecatsim" / "compiled.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.AnnAssign | ast.Assign):
            targets = [node.target] if isinstance(node, ast.AnnAssign) else node.targets
            if any(isinstance(t, ast.Name) and t.id == "CORE" for t in targets):
                value = ast.literal_eval(node.value)  # type: ignore[arg-type]
                return list(value)
    raise SystemExit("setup.py: no CORE tuple in ecatsim/compiled.py")


#: Cython's own run-time code (memoryviews, function objects, ...), one copy in one
#: module for every compiled module instead of a copy in each (decision P14)
SHARED = "ecatsim._cyutility"

#: compiled-only Cython modules (a .pyx, no .py twin): the daemon's responder (decision P9)
PYX = ["ecatsim.ethercat.responder"]


def jobs() -> int:
    """Processes for the build: one per CPU this process may use, at most 8 (a Cython
    translation of one of the larger modules holds about 240 MB)."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # no sched_getaffinity on this platform
        n = os.cpu_count() or 1
    return max(1, min(n, 8))


def core() -> list[Extension]:
    """The Cython-compiled core and the compiled-only modules (``PYX``), or nothing where
    Cython is not installed."""
    from setuptools import Extension

    try:
        from Cython.Build import cythonize
        from Cython.Compiler import Options
    except ImportError:  # no Cython: the pure-Python core runs
        return []
    # every typed memoryview in the core is one-dimensional: a slice is passed and copied
    # as 64 bytes instead of the 208 that room for eight dimensions takes (decision P17)
    Options.buffer_max_dims = 2
    exts = [
        Extension(name, [name.replace(".", "/") + ".py"], optional=True, extra_compile_args=CFLAGS)
        for name in core_modules()
    ] + [
        Extension(name, [name.replace(".", "/") + ".pyx"], optional=True, extra_compile_args=CFLAGS)
        for name in PYX
    ]
    exts.append(
        Extension(
            SHARED, [SHARED.replace(".", "/") + ".c"], optional=True, extra_compile_args=CFLAGS
        )
    )
    built = list(
        cythonize(
            exts,
            # a build directory per version of this file: the generated C of an earlier
            # setting (Cython's shared run-time code too) is never mixed with a new one
            build_dir="build/cython-"
            + hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:12],
            language_level=3,
            quiet=True,
            # Cython's translations in parallel (the C compiler's runs too: build_ext's
            # parallel option below)
            nthreads=jobs(),
            shared_utility_qualified_name=SHARED,
            compiler_directives={
                # the .py files' annotations are for mypy; Cython's types come from the
                # .pxd file beside each module
                "annotation_typing": False,
                "binding": True,
                # the core is not declared safe with the GIL off: a free-threaded
                # interpreter runs the .py modules (ecatsim/compiled.py)
                "freethreading_compatible": False,
            },
        )
    )
    for ext in built:
        ext.optional = True  # cythonize makes new Extension objects: no C compiler, no core
    return built


if __name__ == "__main__":  # setuptools runs setup.py as __main__; a test reads CORE
    from setuptools import setup

    setup(ext_modules=core(), options={"build_ext": {"parallel": jobs()}})
