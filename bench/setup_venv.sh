#!/usr/bin/env bash
# Create bench/.venv with the pinned Python packages the benchmark scripts need.
#
#   bash bench/setup_venv.sh          # create or complete bench/.venv (idempotent)
#   PYTHON=python3.12 bash bench/setup_venv.sh
#
# xatlas + numpy: bench/xatlas_unwrap.py (the xatlas baseline of bench/suite.py).
# scipy + scikit-image: ../shared/tools/make_unruly.py (the suite's generated unruly group).
# The versions are the ones make_unruly.py was tested with (its outputs are byte-identical on them).
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
VENV="$HERE/.venv"
PYTHON="${PYTHON:-python3}"

PINS=(
  "xatlas==0.0.11"
  "numpy==2.4.6"
  "scipy==1.17.1"
  "scikit-image==0.26.0"
)

die() { echo "setup_venv.sh: error: $*" >&2; exit 1; }

command -v "$PYTHON" >/dev/null 2>&1 || die "'$PYTHON' not found (set PYTHON=/path/to/python3)"

if [ ! -x "$VENV/bin/python" ]; then
  echo "creating $VENV with $("$PYTHON" --version 2>&1)"
  "$PYTHON" -m venv "$VENV" || die "'$PYTHON -m venv $VENV' failed (on Debian: apt-get install python3-venv)"
fi

# Already complete? (every pin importable at its exact version) -> nothing to do.
if "$VENV/bin/python" - "${PINS[@]}" <<'PY' 2>/dev/null
import sys
from importlib.metadata import version, PackageNotFoundError
for pin in sys.argv[1:]:
    name, want = pin.split("==")
    try:
        if version(name) != want:
            sys.exit(1)
    except PackageNotFoundError:
        sys.exit(1)
PY
then
  echo "$VENV is up to date: ${PINS[*]}"
  exit 0
fi

echo "installing into $VENV: ${PINS[*]}"
if ! "$VENV/bin/python" -m pip install --disable-pip-version-check --quiet "${PINS[@]}"; then
  die "pip install of ${PINS[*]} into $VENV failed (see pip's message above; PyPI must be reachable)"
fi
"$VENV/bin/python" -c "import xatlas, numpy, scipy, skimage" \
  || die "packages installed but do not import in $VENV"
echo "done: $VENV ($("$VENV/bin/python" --version 2>&1); ${PINS[*]})"
