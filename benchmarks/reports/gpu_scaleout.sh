#!/usr/bin/env bash
# Monte Carlo at scale on a host with several CUDA GPUs, run from the repository root:
#
#     bash benchmarks/reports/gpu_scaleout.sh OUTDIR [BASE_CHECKOUT BASE_NAME]
#
# writes OUTDIR/gpu.txt (devices), multi_gpu.txt (paths/s on 1..N GPUs, tallies against one GPU),
# walk_vs_base.txt (this tree's walk against BASE_CHECKOUT on one GPU, if given), and a
# `layersim mc` ground-truth run of coated gold on every GPU (coated_gold_mc.npz, its log and
# picture) compared with the solver's default plan and with a solve to tol 1e-4
# (compare_*.txt, *.png); SKIP_THROUGHPUT=1 runs only the last. The committed run is
# benchmarks/reports/gpu/scaleout/.
set -uo pipefail   # each step runs even if an earlier one fails; logs say which
out=${1:?usage: gpu_scaleout.sh OUTDIR [BASE_CHECKOUT BASE_NAME]}
mkdir -p "$out"
export PYTHONUNBUFFERED=1
{ nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv; nproc; } > "$out/gpu.txt"
if [ -z "${SKIP_THROUGHPUT:-}" ]; then
python3 benchmarks/montecarlo/multi_gpu.py --seconds 5 2>&1 | tee "$out/multi_gpu.txt"
fi
if [ -n "${2:-}" ] && [ -z "${SKIP_THROUGHPUT:-}" ]; then
    python3 benchmarks/montecarlo/walk_vs_base.py --base "$2" --base-name "${3:-base}" \
        --backends warp-cuda --seconds 2 --repeat 3 2>&1 | tee "$out/walk_vs_base.txt"
fi
scene=benchmarks/scenes/coated_gold.toml
run() { echo "\$ layersim $*"; local t0=$SECONDS; PYTHONSAFEPATH=1 python3 -m layersim.cli "$@"; echo "wall $((SECONDS - t0)) s"; }
run mc "$scene" --wi 0,0 --wi 30,0 --wi 60,0 --paths 1e10 --backend warp-cuda --devices all \
    -o "$out/coated_gold_mc.npz" --quiet 2>&1 | tee "$out/coated_gold_mc.txt"
run compare "$out/coated_gold_mc.npz" "$scene" --plot "$out/compare_default_plan.png" 2>&1 \
    | tee "$out/compare_default_plan.txt"
run solve "$scene" --tol 1e-4 -o "$out/coated_gold_tol1e-4.lsim" --quiet 2>&1 \
    | tee "$out/solve_tol1e-4.txt"
run compare "$out/coated_gold_mc.npz" "$out/coated_gold_tol1e-4.lsim" \
    --plot "$out/compare_tol1e-4.png" 2>&1 | tee "$out/compare_tol1e-4.txt"
rm -f "$out/coated_gold_tol1e-4.lsim"
