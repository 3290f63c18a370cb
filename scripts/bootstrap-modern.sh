#!/usr/bin/env bash
# The second oracle stack: a current dolfinx from PyPI in .venv-modern (git-ignored), next to
# Debian's dolfinx 0.5.2 in .venv. The PyPI wheel dolfinx-solver-real ships DOLFINx 0.11 with
# its own real-scalar PETSc and pulls the PyPI builds of MPICH, mpi4py, basix, FFCx, UFL and
# NumPy 2; it exists for CPython >= 3.12 only. Safe to run again: skipped when installed.
#
# Exit codes: 0 ready; 3 the stack cannot be installed on this machine (no Python >= 3.12,
# or PyPI unreachable), with the reason on stderr; 1 anything else.
# Environment: MJED_MODERN_PYTHON=/path/to/python3.12 picks the interpreter.
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=.venv-modern
# The wheel fixes the whole FEniCS stack; the rest is what the oracle tests need.
REQUIREMENTS=(
  "dolfinx-solver-real==0.11.0.post0"
  "scipy>=1.11" "pytest>=7" "pytest-xdist>=3" "hypothesis>=6" "meshio>=5.3"
  "felupe==11.3.0" "tensortrax==0.29.0"  # checked by tests/test_adapters_felupe.py (conformance/adapters/felupe.py)
  "numba==0.68.1"  # the compiled backend (mjed/compiled), checked by tests/test_compiled*.py
)
stamp=$VENV/.mjed-installed
want="${REQUIREMENTS[*]}"

if [ -x "$VENV/bin/python" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && [ ! pyproject.toml -nt "$stamp" ]; then
  exit 0
fi

# A CPython >= 3.12: the one asked for, one on PATH, a pyenv build, or one uv manages.
is_312() { "$1" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' 2>/dev/null; }
candidates=()
[ -n "${MJED_MODERN_PYTHON:-}" ] && candidates+=("$MJED_MODERN_PYTHON")
for name in python3.13 python3.12; do
  command -v "$name" >/dev/null 2>&1 && candidates+=("$(command -v "$name")")
done
for p in "${PYENV_ROOT:-$HOME/.pyenv}"/versions/3.1[2-9]*/bin/python; do
  [ -x "$p" ] && candidates+=("$p")
done
if command -v uv >/dev/null 2>&1; then
  p=$(uv python find '>=3.12' 2>/dev/null || true)
  [ -n "$p" ] && candidates+=("$p")
fi
PY=""
for c in "${candidates[@]}"; do
  if is_312 "$c"; then PY=$c; break; fi
done
if [ -z "$PY" ]; then
  echo "bootstrap-modern: no CPython >= 3.12 found (looked at \$MJED_MODERN_PYTHON, python3.13/3.12 on PATH," >&2
  echo "  pyenv versions, uv). dolfinx-solver-real has wheels for Python >= 3.12 only. Install one, e.g." >&2
  echo "  'pyenv install 3.12' or 'uv python install 3.12', or set MJED_MODERN_PYTHON." >&2
  exit 3
fi

start=$(date +%s)
if [ ! -x "$VENV/bin/python" ]; then
  echo "bootstrap-modern: creating $VENV with $PY ($("$PY" --version 2>&1))" >&2
  "$PY" -m venv "$VENV"
fi
# pip's wheel cache (~/.cache/pip) makes a re-install offline and quick; about 130 MB the first time.
if ! "$VENV/bin/python" -m pip install --quiet "${REQUIREMENTS[@]}" >&2; then
  if ! "$VENV/bin/python" -m pip download --quiet --no-deps --dest "$(mktemp -d)" "pip" >/dev/null 2>&1; then
    echo "bootstrap-modern: PyPI is not reachable from this machine; the modern stack cannot be installed." >&2
    exit 3
  fi
  echo "bootstrap-modern: pip install of ${REQUIREMENTS[*]} failed (PyPI is reachable)." >&2
  exit 1
fi
# The project itself, editable and without its dependencies (installed above); the venv's
# own setuptools builds it, so nothing else is fetched.
"$VENV/bin/python" -m pip install --quiet --no-build-isolation --no-deps -e . >&2
# Check that the stack really loads (the wheel needs its MPI loaded before dolfinx).
"$VENV/bin/python" -c 'from reference_fem import compat; compat.import_dolfinx(); print("bootstrap-modern: dolfinx", compat.import_dolfinx().__version__, "ready")' >&2
echo "$want" > "$stamp"
echo "bootstrap-modern: done in $(( $(date +%s) - start )) s" >&2
