#!/usr/bin/env bash
# GPU measurements, run from the repository root on a machine with a CUDA GPU:
#
#     bash benchmarks/reports/gpu_suite.sh OUTDIR [--quick]
#
# writes OUTDIR/gpu.txt (device), mc_throughput_gpu.{json,txt} (paths/s per backend: warp-cuda,
# OpenCL on the GPU, warp-cpu, PoCL if present), projection_paths_gpu.{json,txt} (numeric
# projection on the GPU against the host semi-analytic path) and, unless --quick is given to skip
# it, report/ (the full `layersim bench` with the GPU Monte Carlo backends). The committed run
# is benchmarks/reports/gpu/.
set -uo pipefail   # each step runs even if an earlier one fails; logs say which
out=${1:?usage: gpu_suite.sh OUTDIR [--quick]}
mkdir -p "$out"
export PYTHONUNBUFFERED=1
{ nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv; nproc; } > "$out/gpu.txt"
python3 benchmarks/montecarlo/mc_throughput.py --seconds 4 --json "$out/mc_throughput_gpu.json" \
    2>&1 | tee "$out/mc_throughput_gpu.txt"
python3 benchmarks/speed/projection_paths.py --devices cpu cuda \
    --json "$out/projection_paths_gpu.json" \
    2>&1 | tee "$out/projection_paths_gpu.txt"
if [ "${2:-}" != "--quick" ]; then
    python3 -m layersim.cli bench --stability --out "$out/report" --backend warp-cuda \
        --backend opencl 2>&1 | tee "$out/bench.log"
fi
