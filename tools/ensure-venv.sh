#!/usr/bin/env bash
# Make .venv hold the pinned dependencies (requirements-test.lock) and ecatsim itself
# (editable, the compiled core built). A second run with the same lock, pyproject and
# sources reuses the venv without reinstalling.
#   tools/ensure-venv.sh            # from the project root or anywhere
set -euo pipefail
cd "$(dirname "$0")/.."
stamp=.venv/.ecatsim-installed
# the compiled core is built from the package's own .py/.pxd files and the responder's
# .pyx (setup.py): any change to them rebuilds it
want=$(cat requirements-test.lock pyproject.toml setup.py $(git ls-files 'ecatsim/*.py' \
    'ecatsim/*.pxd' 'ecatsim/*.pyx' 2>/dev/null \
    || find ecatsim -name '*.py' -o -name '*.pxd' -o -name '*.pyx' | sort) \
    | sha256sum | cut -d' ' -f1)
if [ -x .venv/bin/python ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] \
        && .venv/bin/python -c 'import ecatsim' 2>/dev/null; then
    echo "venv: .venv is up to date (delete $stamp to reinstall)"
    exit 0
fi
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
.venv/bin/python -m pip install --quiet --disable-pip-version-check -r requirements-test.lock
.venv/bin/python -m pip install --quiet --disable-pip-version-check --no-deps -e .
echo "$want" > "$stamp"
echo "venv: installed into .venv"
