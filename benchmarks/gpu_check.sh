#!/usr/bin/env bash
# The CUDA check, one command for whoever next has an NVIDIA GPU (steps 1-5 took about 4
# minutes on an H200, 2026-12-04), run from an installed checkout (pip install -e '.[test]'):
#
#     bash benchmarks/gpu_check.sh [OUT]          # OUT defaults to out/gpu-check
#
# Under OUT, each step's log and results, and summary.json (each step's exit code and time):
#   1. tests.xml, tests.log: the CUDA tests (tests/test_dem_cuda.py, the sm_90 compile test)
#   2. throughput.csv/.json: particle-steps/s at B = 1, 16, 64, 256, 1024, 4096 RVEs x 400
#      discs, float64 and float32, one process per case (undamped, sheared at 1e-5 a step)
#   3. agreement.csv/.json: CUDA against the CPU on a sheared batch of 16 RVEs, per float type
#   4. condensed.json: the default tangent's condensation (condensed-sticking: --sliding
#      stick) by the batched CG on CUDA against scipy's LU on the
#      host, 600 sheared RVEs of 400 discs, the specimen's batch (iterations, largest
#      difference; seconds of the CG's host assembly and device solve, of the LU, of the
#      same assembled on the device, and of 200 DEM steps of the same batch on CUDA)
#   5. specimen/: the paper's specimen (10 x 15 Q4, 600 RVEs of 400 discs), its first 5 load
#      steps of 0.1 % (those of --steps 100 --axial-strain 0.1), steps.csv and summary.json
#   6. paths.csv/.json: the engine's two step paths from one snapshot, the two-kernel step
#      (the engine's CUDA path) and the block path (one thread block an RVE, many steps a
#      launch), particle-steps/s at B = 1, 64, 1024, 4096 RVEs x 400 discs, float64 and
#      float32, their ratio and the difference of their stresses (gpu_check.py paths)
#   7. block_specimen/: step 5 again with the block path taken (gpu_check.py block-specimen)
# Every step runs under its own time limit; one that fails or runs out is recorded and the
# others still run. Exit 0 only when every step passed; 2 at once where there is no GPU.
# GPU_CHECK_SMOKE=1 runs every step on the CPU at toy sizes instead (tests/test_gpu_check.py).
set -uo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python}
OUT=${1:-out/gpu-check}
# limits [s] of the steps (sum 480 s; on an H200 with a cold kernel cache steps 1-5 took 37,
# 50, 84, 16 and 46 s, 2026-12-04; steps 6 and 7 have not run on a GPU yet)
T_TESTS=${T_TESTS:-55} T_THROUGHPUT=${T_THROUGHPUT:-80} T_AGREEMENT=${T_AGREEMENT:-100}
T_CONDENSED=${T_CONDENSED:-30} T_SPECIMEN=${T_SPECIMEN:-60} T_PATHS=${T_PATHS:-95}
T_BLOCK_SPECIMEN=${T_BLOCK_SPECIMEN:-60}

if [ "${GPU_CHECK_SMOKE:-0}" = 1 ]; then  # the script itself, on the CPU, at toy sizes
    DEV=cpu DEVICE="cpu (smoke)" TESTS=(tests/test_dem_cuda.py) BATCHES=1,2 PARTICLES=30
    AGREE=(--batch 2 --particles 30 --strain 2e-4) SPECIMEN=(--elements 1 1 --particles 30)
    CONDENSED=(--batch 2 --particles 30 --strain 2e-4 --sliding stick)
    PATHS=(--batches 1,2 --particles 30 --seconds 0.1)
else
    DEVICE=$("$PYTHON" benchmarks/gpu_check.py require-cuda | tail -n 1) || exit 2
    DEV=cuda TESTS=(tests/test_dem_cuda.py tests/test_cuda_compile.py)
    BATCHES=1,16,64,256,1024,4096 PARTICLES=400 AGREE=(--batch 16 --particles 400)
    CONDENSED=(--batch 600 --particles 400 --sliding stick)
    SPECIMEN=(--scale full) PATHS=(--batches 1,64,1024,4096 --particles 400 --seconds 0.5)
fi
mkdir -p "$OUT"
echo "gpu_check: $DEVICE, commit $(git rev-parse --short HEAD 2>/dev/null || echo unknown), out $OUT"

declare -A RC SECONDS_OF
run_step() {  # name limit command...: runs it under the limit, logs to OUT/name.log
    local name=$1 limit=$2; shift 2
    local t0=$SECONDS
    echo "== $name (limit ${limit} s)"
    timeout -s TERM -k 10 "$limit" "$@" >"$OUT/$name.log" 2>&1
    RC[$name]=$?
    SECONDS_OF[$name]=$((SECONDS - t0))
    tail -n 15 "$OUT/$name.log"
    echo "== $name: exit ${RC[$name]} after ${SECONDS_OF[$name]} s"
}

run_step tests "$T_TESTS" "$PYTHON" -m pytest -q "${TESTS[@]}" --junitxml="$OUT/tests.xml"
run_step throughput "$T_THROUGHPUT" "$PYTHON" benchmarks/dem_throughput.py --device $DEV \
    --batches $BATCHES --particles $PARTICLES --dtypes float64,float32 --seconds 0.5 \
    --repeats 1 --no-yade --no-lammps --out "$OUT/throughput.csv"
run_step agreement "$T_AGREEMENT" "$PYTHON" benchmarks/gpu_check.py agreement \
    --device $DEV --reference cpu "${AGREE[@]}" --out "$OUT"
run_step condensed "$T_CONDENSED" "$PYTHON" benchmarks/gpu_check.py condensed \
    --device $DEV "${CONDENSED[@]}" --out "$OUT"
run_step specimen "$T_SPECIMEN" "$PYTHON" -m granular_material.cli biaxial "${SPECIMEN[@]}" \
    --device $DEV --steps 5 --axial-strain 0.005 --drive continue --no-progress \
    --out "$OUT/specimen"
run_step paths "$T_PATHS" "$PYTHON" benchmarks/gpu_check.py paths --device $DEV \
    "${PATHS[@]}" --out "$OUT"
run_step block_specimen "$T_BLOCK_SPECIMEN" "$PYTHON" benchmarks/gpu_check.py block-specimen \
    -- biaxial "${SPECIMEN[@]}" --device $DEV --steps 5 --axial-strain 0.005 \
    --drive continue --no-progress --out "$OUT/block_specimen"

status=0
{
    echo "{"
    echo "  \"device\": \"$DEVICE\","
    echo "  \"commit\": \"$(git rev-parse --short HEAD 2>/dev/null || echo unknown)\","
    echo "  \"steps\": {"
    sep=""
    for name in tests throughput agreement condensed specimen paths block_specimen; do
        printf '%s    "%s": {"exit": %d, "seconds": %d}' "$sep" "$name" "${RC[$name]}" \
            "${SECONDS_OF[$name]}"
        sep=$',\n'
        [ "${RC[$name]}" -eq 0 ] || status=1
    done
    printf '\n  }\n}\n'
} >"$OUT/summary.json"
cat "$OUT/summary.json"
exit $status
