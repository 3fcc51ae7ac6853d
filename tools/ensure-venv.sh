#!/usr/bin/env bash
# Make .venv hold the pinned dependencies (requirements-test.lock) and ecatsim itself
# (editable, the compiled core built). A second run with the same lock, pyproject and C
# sources reuses the venv without reinstalling.
#   tools/ensure-venv.sh            # from the project root or anywhere
set -euo pipefail
cd "$(dirname "$0")/.."
stamp=.venv/.ecatsim-installed
# the compiled core is built from the package's own .py/.pxd files (setup.py): any change
# to them, or to the C paths, rebuilds it
want=$(cat requirements-test.lock pyproject.toml setup.py $(git ls-files 'ecatsim/*.c' \
    'ecatsim/*.h' 'ecatsim/*.py' 'ecatsim/*.pxd' 2>/dev/null \
    || find ecatsim -name '*.[ch]' -o -name '*.py' -o -name '*.pxd' | sort) \
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
