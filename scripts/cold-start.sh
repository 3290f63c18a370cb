#!/usr/bin/env bash
# What a newcomer pays: the README's commands run with every JIT cache empty. A benchmark that
# prints figures, not a test (it fails only if a command it times fails).
#
#   scripts/cold-start.sh [test] [demo] [debian] [modern]     (default: test demo)
#
#   test    make test's legs in order: bootstrap, the Debian leg (lint + pytest), the modern
#           stack's bootstrap, the modern leg, the cross-release check
#   demo    make demo's legs: bootstrap, the modern stack's bootstrap, mjed-verify all
#   debian  only the Debian leg; modern: only the modern leg (and its bootstrap)
#
# Each target starts from its own new, empty cache folder: XDG_CACHE_HOME (dolfinx/FFCx's
# JIT cache ~/.cache/fenics, pip's cache, the generated MJED kernels ~/.cache/mjed/kernels),
# MJED_KERNEL_CACHE, NUMBA_CACHE_DIR (Numba's compiled overloads, which would otherwise sit
# in __pycache__ beside the sources) and PYTHONPYCACHEPREFIX (bytecode, as on a fresh clone).
# The virtual environments are kept (delete .venv and .venv-modern first for a fresh clone's
# bootstrap). Printed per target: wall time per leg, pytest's 40 slowest tests, and the
# compile census (scripts/compile_census.py): FFCx forms and Numba overloads compiled, in all
# and by test module, test function or report study. Logs and per-test census files go to
# $COLD_OUT (default reports/cold-start/<date>); the caches are deleted at exit
# (COLD_KEEP=1 keeps them).
set -uo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(test demo)
out=${COLD_OUT:-reports/cold-start/$(date +%Y%m%d-%H%M%S)}
mkdir -p "$out"
out=$(cd "$out" && pwd)
caches=()
cleanup() {
  if [ "${COLD_KEEP:-0}" != 1 ]; then
    for d in "${caches[@]}"; do rm -rf "$d"; done
  fi
}
trap cleanup EXIT

summary="$out/summary.txt"
say() { echo "$*" | tee -a "$summary"; }

fresh_caches() {
  local dir
  dir=$(mktemp -d "${TMPDIR:-/tmp}/mjed-cold.XXXXXX")
  caches+=("$dir")
  export XDG_CACHE_HOME=$dir/cache
  export MJED_KERNEL_CACHE=$dir/cache/mjed/kernels
  export NUMBA_CACHE_DIR=$dir/cache/numba
  export PYTHONPYCACHEPREFIX=$dir/pycache
  say "caches: $dir (empty)"
}

# leg NAME CENSUS COMMAND...: run and time one leg, its output in $out/NAME.log
failed=0
leg() {
  local name=$1 census=$2
  shift 2
  local t0 rc
  t0=$(date +%s.%N)
  rm -f "$out/$census.jsonl"
  if [ "$census" != - ]; then
    MJED_COMPILE_CENSUS="$out/$census.jsonl" PYTHONPATH="$root/scripts${PYTHONPATH:+:$PYTHONPATH}" \
      PYTEST_ADDOPTS="-p compile_census --durations=40 ${PYTEST_ADDOPTS:-}" \
      "$@" >"$out/$name.log" 2>&1
  else
    "$@" >"$out/$name.log" 2>&1
  fi
  rc=$?
  local s
  s=$(python3 -c "import time; print(f'{time.time() - $t0:.0f}')")
  say "$(printf '  %-20s %6s s  exit %s  (%s)' "$name" "$s" "$rc" "$*")"
  [ "$rc" -ne 0 ] && [ "$rc" -ne 3 ] && failed=1
  return 0
}

census_of() {
  # the session's totals (the controller's snapshots, exact with parallel workers), then the
  # per-test records
  sed -n '/^compile census/,/per-test records/p' "$out/$1.log" | tee -a "$summary"
  [ -f "$out/$1.jsonl" ] && python3 scripts/compile_census.py summary "$out/$1.jsonl" | tee -a "$summary"
  return 0
}

slowest() {
  # pytest's --durations block, as printed in the leg's log
  sed -n '/slowest 40 durations/,/^$/p' "$out/$1.log" | head -42 | tee -a "$summary"
}

say "cold start on $(hostname) ($(nproc) cores, $(awk '/MemTotal/ {printf "%.0f GiB", $2/1048576}' /proc/meminfo)), $(date -Iseconds), $(git rev-parse --short HEAD)$(git diff --quiet || echo ' (modified)'), load $(cut -d' ' -f1-3 /proc/loadavg)"
for target in "${targets[@]}"; do
  say ""
  say "== $target"
  fresh_caches
  t_start=$(date +%s)
  case $target in
    test)
      leg bootstrap - make --no-print-directory bootstrap
      leg debian debian make --no-print-directory test-debian
      leg bootstrap-modern - make --no-print-directory bootstrap-modern
      leg modern modern make --no-print-directory test-modern
      leg cross-release - .venv/bin/python -m comparisons.cross_release check --json "$out/cross_release.json"
      ;;
    debian)
      leg debian debian make --no-print-directory test-debian
      ;;
    modern)
      leg bootstrap-modern - make --no-print-directory bootstrap-modern
      leg modern modern make --no-print-directory test-modern
      ;;
    demo)
      leg bootstrap - make --no-print-directory bootstrap
      leg bootstrap-modern - make --no-print-directory bootstrap-modern
      leg demo demo .venv/bin/python scripts/compile_census.py demo all --out "$out/report"
      ;;
    *)
      echo "cold-start: unknown target $target (test, demo, debian, modern)" >&2
      exit 2
      ;;
  esac
  say "  $target in all: $(( $(date +%s) - t_start )) s"
  case $target in
    test) slowest debian; census_of debian; slowest modern; census_of modern ;;
    debian) slowest debian; census_of debian ;;
    modern) slowest modern; census_of modern ;;
    demo) census_of demo ;;
  esac
done
say ""
say "figures: $summary"
exit $failed
