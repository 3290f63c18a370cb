#!/usr/bin/env bash
# Every GPU figure of the project in one run on a machine with an NVIDIA GPU, written under
# $OUT (default ./gpu-session): docs/studies/timing.md, "A GPU session".
#
#   OUT=/path/to/out scripts/gpu_session.sh [STEP ...]
#
# Steps (all by default, in this order): env bench kits liver organ peer regs scatter pack. Each
# step runs under its own time limit (seconds, STEP_LIMIT_<step>; together 1025 s: on a device
# lent 600 s per command, run `env bench peer`, `kits regs pack`, `liver organ pack`, then
# `env scatter pack`), with its
# log in $WORK/logs/<step>.log (WORK default /tmp/gpu-session-work, packed into results.tar.xz) and
# its last lines printed; a failed or timed-out step is reported loudly and the next one still
# runs. The summary at the end (also $OUT/summary.txt) lists each step's exit code (124: timed
# out) and seconds; the script exits 1 if any step failed. $OUT holds at most 9 files.
#
#   env    the machine: nvidia-smi, Python, NumPy, Numba, whether the oracle (dolfinx) is here
#   bench  python -m comparisons.timing.hardware --no-cpu --json $OUT/hardware_bench.json: the
#          GPU section (1e4 to 1e7 tets, with the compiled CPU backend on all cores of the same
#          machine for the ratio); BENCH_ARGS="" gives the CPU section too (minutes more)
#   kits   conformance kits on cube-paper, every material and state, filled by the cuda
#          backend in FP64 and FP32 (python -m conformance.adapters.mjed_backend --kit) and
#          by mjed's NumPy engine; each GPU kit against the CPU one (max relative
#          difference); `mjed-verify check` on each where dolfinx is importable. The same on
#          cube-small (no probes), kept for `pack` so that a machine with the oracle checks them
#   liver  mjed-verify liver --backends cuda,numba on the paper-size liver (30 steps, three
#          models, the oscillation study)
#   organ  the same on liver-100k (100,412 tets, 18,827 nodes; 5 steps, no oscillation study),
#          the CPU runs with Jacobi CG too (a kept LU of 56,000 dofs takes tens of seconds)
#   peer   python -m comparisons.timing.jax_peer: the same cubes by JAX autodiff per element
#          (vmap of grad and hessian, XLA) where JAX sees the GPU, beside bench's figures
#   regs   python -m comparisons.timing.gpu_occupancy --json $OUT/gpu_occupancy.json: registers,
#          local memory (spills) and theoretical occupancy of every CUDA cell kernel (MJED's and
#          the classical element's, FP64 and FP32, force and force+stiffness); after `kits`,
#          MJED's kernels load from the kernel cache; those not started within 85 s are listed
#          as not read (exit 0), a kernel that fails to compile fails the step
#   scatter python -m comparisons.timing.gpu_scatter --json $OUT/gpu_scatter.json: are the 144
#          atomic adds per cell into the CSR values what bounds force+stiffness? NeoHookean,
#          cubes of 1e5, 1e6 (and 1e7 if started within 70 s) tets, FP64 and FP32: the atomic
#          f+K kernel, the element kernel (plain stores per cell) and the gather kernel apart and
#          together, the edge kernel (six edge blocks per cell) and its gather apart and
#          together, the force kernel for reference, each checked against the atomic path first
#          (SCATTER_ARGS for other options); at most 180 s, most of it compiling and the 1e7
#          cube's host set-up
#   pack   $OUT/results.tar.xz: the logs, check JSONs and figures; $OUT/kits-cube-small.tar.xz:
#          the GPU-filled cube-small kits (inputs and outputs), for `mjed-verify check` elsewhere
#
# Afterwards: copy $OUT/hardware_bench.json to docs/studies/gpu_figures.json (the report's gpu
# section reads it) and write the figures into docs/studies/timing.md with the device and date.
# No dolfinx on the GPU machine: unpack kits-cube-small.tar.xz on a machine with the oracle and
#   mjed-verify check kits/cube-small-float64 && mjed-verify check kits/cube-small-float32
set -u
cd "$(dirname "$0")/.."
OUT=${OUT:-$PWD/gpu-session}
WORK=${WORK:-/tmp/gpu-session-work}
PY=${PYTHON:-python3}
mkdir -p "$OUT" "$WORK/logs"
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
export MJED_KERNEL_CACHE=${MJED_KERNEL_CACHE:-$WORK/kernels}
unset NUMBA_ENABLE_CUDASIM # a real device, never the simulator
VERIFY=("$PY" -m comparisons.cli)
ADAPTER=("$PY" -m conformance.adapters.mjed_backend)
# Three device commands: `env bench peer` (at most 225 s), `kits regs pack` (380 s), `liver
# organ pack` (260 s); and `env scatter pack` (215 s) for the scatter experiment. Measured on an H200 (2026-11-26): env 8 s, bench 105 s, peer 30 s, liver
# 54 s, organ 98 s; kits about 95 s per precision, nearly all of it compiling the 20 CUDA
# kernels of that precision (cube-paper FP64: 76 s; then cube-small in 1 s from the kernel
# cache): 190 s for both, so 250 s leaves room for the NumPy kit and a slower compile; regs
# stops compiling at 85 s (its --budget) within its 110 s.
declare -A LIMIT=([env]=15 [bench]=150 [kits]=250 [liver]=90 [organ]=150 [peer]=60 [regs]=110
    [scatter]=180 [pack]=20)
BENCH_ARGS=${BENCH_ARGS---no-cpu}
export XLA_PYTHON_CLIENT_PREALLOCATE=false # JAX takes memory as it needs it, not 75 % at start
SUMMARY=()
FAILED=0

step_env() {
    nvidia-smi || echo "FAILED: nvidia-smi"
    "$PY" - <<'EOF'
import platform, sys, numpy, scipy
print("python", platform.python_version(), "numpy", numpy.__version__, "scipy", scipy.__version__)
import numba
from numba import cuda
print("numba", numba.__version__, "cuda available:", cuda.is_available())
if not cuda.is_available():
    sys.exit("FAILED: numba.cuda finds no GPU: every GPU step below will say 'not run: no GPU'")
cuda.detect()
try:
    import dolfinx
    print("dolfinx", dolfinx.__version__, ": kits are checked here")
except ImportError:
    print("no dolfinx: kits are filled and compared with the CPU kernel here, checked elsewhere")
try:
    import jax
    print("jax", jax.__version__, "backend", jax.default_backend(), jax.devices())
except Exception as exc:  # the peer step says it is not run
    print("no JAX on the GPU:", exc)
EOF
}

step_bench() {
    # shellcheck disable=SC2086 # BENCH_ARGS is a list of options
    "$PY" -m comparisons.timing.hardware $BENCH_ARGS --json "$OUT/hardware_bench.json"
}

have_oracle() { "$PY" -c "import dolfinx" 2>/dev/null; }

# kit MESH DTYPE [export options]: export, fill with the cuda backend, check when possible
kit() {
    local mesh=$1 dtype=$2 precision=double name="$WORK/kits/$1-$2" rc=0
    shift 2
    [ "$dtype" = float32 ] && precision=single
    rm -rf "$name"
    "${VERIFY[@]}" export "$name" --mesh "$mesh" --material all --precision "$precision" "$@" || return 1
    "${ADAPTER[@]}" --kit "$name" --backend cuda --dtype "$dtype" || rc=1
    if have_oracle; then
        "${VERIFY[@]}" check "$name" --out "$WORK/check" --json "$WORK/check-$mesh-$dtype.json" \
            --quiet || rc=1
    fi
    return $rc
}

# compare_kits GPU_KIT CPU_KIT: every case's force and stiffness, GPU against CPU, per material
compare_kits() {
    "$PY" -m conformance.kit.agreement "$1" "$2"
}

step_kits() {
    local rc=0 cpu="$WORK/kits/cube-paper-cpu"
    rm -rf "$cpu"
    "${VERIFY[@]}" export "$cpu" --mesh cube-paper --material all --no-probes || rc=1
    "${ADAPTER[@]}" --kit "$cpu" --backend numpy || rc=1
    for dtype in float64 float32; do
        kit cube-paper "$dtype" --no-probes || { echo "FAILED: cube-paper $dtype"; rc=1; }
        compare_kits "$WORK/kits/cube-paper-$dtype" "$cpu" || rc=1
        kit cube-small "$dtype" --no-probes || { echo "FAILED: cube-small $dtype"; rc=1; }
    done
    return $rc
}

# gpu_runs JSON: fails unless the liver result holds completed cuda runs (a machine without a
# GPU leaves them out and says so; that must not pass as a GPU session)
gpu_runs() {
    "$PY" - "$1" <<'EOF'
import json, sys
runs = json.load(open(sys.argv[1]))["data"]["runs"]
gpu = [r for r in runs if r["backend"] == "cuda"]
bad = [f"{r['model']}: {r['error']}" for r in gpu if r["error"]]
for r in runs:
    print(f"  {r['model']:26s} {r['backend']:6s} FPS {r['fps'] or 0:8.1f}  CG/step {r['cg_iterations_mean'] or 0:7.1f}")
sys.exit("FAILED: no cuda run" if not gpu else ("FAILED: " + "; ".join(bad) if bad else 0))
EOF
}

step_liver() {
    "${VERIFY[@]}" liver --backends cuda,numba --no-series --out "$WORK/liver" \
        --json "$OUT/liver.json"
    local rc=$? # 3: a target missed (reported), or cuda not run (then gpu_runs fails)
    gpu_runs "$OUT/liver.json" || return 1
    [ $rc -eq 3 ] || return $rc
}

step_organ() {
    "${VERIFY[@]}" liver --mesh liver-100k --steps 5 --solver jacobi --backends cuda,numba \
        --no-oscillation --no-series --out "$WORK/organ" --json "$OUT/liver-100k.json"
    local rc=$? # 3 by design: 5 steps, no oscillation study
    gpu_runs "$OUT/liver-100k.json" || return 1
    [ $rc -eq 3 ] || return $rc
}

step_peer() {
    "$PY" -m comparisons.timing.jax_peer --json "$OUT/jax_peer.json" \
        --against "$OUT/hardware_bench.json"
}

step_regs() {
    # REGS_ARGS (default "--budget 85") e.g. "--engines classical --budget 200" for one engine
    # shellcheck disable=SC2086 # word splitting of the arguments is meant
    "$PY" -m comparisons.timing.gpu_occupancy ${REGS_ARGS:---budget 85} --json "$OUT/gpu_occupancy.json"
}

step_scatter() {
    # shellcheck disable=SC2086 # SCATTER_ARGS is a list of options
    "$PY" -m comparisons.timing.gpu_scatter ${SCATTER_ARGS:-} --json "$OUT/gpu_scatter.json"
}

step_pack() {
    local rc=0
    if [ -d "$WORK/kits/cube-small-float64" ]; then
        rm -rf "$WORK/pack" && mkdir -p "$WORK/pack/kits"
        for d in float64 float32; do
            cp -r "$WORK/kits/cube-small-$d" "$WORK/pack/kits/" || rc=1
        done
        tar -C "$WORK/pack" -cJf "$OUT/kits-cube-small.tar.xz" kits || rc=1
    fi
    tar -C "$WORK" -cJf "$OUT/results.tar.xz" --ignore-failed-read logs liver organ \
        $(cd "$WORK" && ls check-*.json 2>/dev/null) || rc=1
    ls -la "$OUT"
    return $rc
}

run_step() {
    local step=$1 limit=${LIMIT[$1]} start rc
    limit=$(eval echo "\${STEP_LIMIT_$step:-$limit}")
    echo "=== $step (limit ${limit} s) ==="
    start=$(date +%s)
    # the step in its own process, killed with its children past its limit
    timeout --kill-after=10 "$limit" bash -c "$(declare -f); $(declare -p VERIFY ADAPTER PY OUT WORK \
        BENCH_ARGS); \
        step_$step" >"$WORK/logs/$step.log" 2>&1
    rc=$?
    tail -n 25 "$WORK/logs/$step.log"
    local seconds=$(($(date +%s) - start))
    if [ $rc -ne 0 ]; then
        echo "!!! STEP $step FAILED (exit $rc$([ $rc -eq 124 ] && echo ', timed out')) after ${seconds} s: see $WORK/logs/$step.log"
        FAILED=1
    fi
    SUMMARY+=("$(printf '%-6s exit %3d  %4d s' "$step" "$rc" "$seconds")")
}

STEPS=("$@")
[ ${#STEPS[@]} -eq 0 ] && STEPS=(env bench kits liver organ peer regs scatter pack)
for s in "${STEPS[@]}"; do
    if [ -z "${LIMIT[$s]+x}" ]; then
        echo "unknown step $s (env bench kits liver organ peer regs scatter pack)"
        exit 2
    fi
done
for s in "${STEPS[@]}"; do run_step "$s"; done
echo "=== summary (exit 124: timed out) ===" | tee "$OUT/summary.txt"
printf '%s\n' "${SUMMARY[@]}" | tee -a "$OUT/summary.txt"
exit $FAILED
