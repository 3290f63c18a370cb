#!/usr/bin/env bash
# Make the project runnable on a fresh Debian 12 machine: system packages (apt), a virtual
# environment that sees them (--system-site-packages, so dolfinx, PETSc and NumPy come from
# Debian), and this project installed editable in it. Safe to run again: each step is skipped
# when already done.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PACKAGES=(
  python3 python3-venv python3-pip python3-setuptools python3-wheel
  python3-numpy python3-scipy python3-matplotlib
  python3-dolfinx python3-petsc4py python3-mpi4py python3-ufl
  python3-gmsh python3-meshio python3-h5py
  python3-pytest python3-pytest-xdist python3-hypothesis
  python3-sphinx python3-myst-parser python3-sphinx-rtd-theme libjs-mathjax fonts-mathjax
  chromium chromium-driver
  python3-numba python3-sfepy
)

missing=()
for p in "${APT_PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -gt 0 ]; then
  cmd="apt-get update && apt-get install -y --no-install-recommends ${missing[*]}"
  if [ "$(id -u)" -eq 0 ]; then
    echo "bootstrap: installing Debian packages: ${missing[*]}" >&2
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -q >&2
    apt-get install -y -q --no-install-recommends "${missing[@]}" >&2
  else
    echo "bootstrap: these Debian packages are missing: ${missing[*]}" >&2
    echo "bootstrap: run this as root, then run make again:" >&2
    echo "  sudo sh -c '$cmd'" >&2
    exit 1
  fi
fi

# The interpreter that owns Debian's dist-packages (not a pyenv or conda python on PATH).
SYS_PY=/usr/bin/python3
if [ ! -x .venv/bin/python ]; then
  echo "bootstrap: creating .venv (with system site packages)" >&2
  "$SYS_PY" -m venv --system-site-packages .venv
fi

stamp=.venv/.mjed-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "bootstrap: installing the project (editable) into .venv" >&2
  # --no-build-isolation and --no-deps: build with Debian's setuptools and use Debian's
  # NumPy/SciPy, so nothing is fetched from PyPI and the oracle sees the same NumPy.
  .venv/bin/python -m pip install --quiet --no-build-isolation --no-deps -e . >&2
  touch "$stamp"
fi

# ruff, the lint and format gate of `make test` (pinned: a newer release may format differently).
RUFF_PIN="ruff==0.17.6"
ruff_stamp=.venv/.ruff-installed
if [ ! -f "$ruff_stamp" ] || [ "$(cat "$ruff_stamp")" != "$RUFF_PIN" ]; then
  echo "bootstrap: installing $RUFF_PIN (PyPI) into .venv for the lint gate" >&2
  .venv/bin/python -m pip install --quiet "$RUFF_PIN" >&2
  echo "$RUFF_PIN" > "$ruff_stamp"
fi

# FElupe, a third-party FE library the conformance adapters check (conformance/adapters/felupe.py;
# its energies were read from this release), with tensortrax for FElupe's automatic
# differentiation (Hyperelastic). Both pure Python on NumPy/SciPy: --no-deps keeps Debian's
# NumPy and SciPy. Optional: without PyPI the FElupe tests skip, saying why.
FELUPE_PINS=("felupe==11.3.0" "tensortrax==0.29.0")
felupe_stamp=.venv/.felupe-installed
if [ ! -f "$felupe_stamp" ] || [ "$(cat "$felupe_stamp")" != "${FELUPE_PINS[*]}" ]; then
  if .venv/bin/python -m pip install --quiet --no-deps "${FELUPE_PINS[@]}" >&2; then
    echo "${FELUPE_PINS[*]}" > "$felupe_stamp"
  else
    echo "bootstrap: could not install ${FELUPE_PINS[*]} from PyPI (offline?); the FElupe adapter tests will skip." >&2
  fi
fi
