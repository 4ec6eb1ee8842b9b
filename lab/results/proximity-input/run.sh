#!/usr/bin/env bash
# The runs behind docs/results/proximity-input/README.md, from the repository root on the
# project's 2-core AMD EPYC (AVX2), one Torch thread each, two at a time. Each run's
# config.json and metrics.csv are copied to trials/<n>/seed=S/ (weights are not
# committed); table.py prints the tables of README.md.
set -euo pipefail
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
here=docs/results/proximity-input
runs=${RUNS:-runs/proximity}
train() {  # train SIZE SEED [FLAGS...]: the main job's preset with the proximity input
    local size=$1 seed=$2; shift 2
    spikectl train guided --sizes.inputs target proximity --seed "$seed" "$@" \
        --run-dir "$runs/$size-seed$seed"
    mkdir -p "$here/trials/$size/seed=$seed"
    cp "$runs/$size-seed$seed/config.json" "$runs/$size-seed$seed/metrics.csv" \
        "$here/trials/$size/seed=$seed/"
}
for seed in 0 1 2; do train n8 "$seed"; done
# At 16 and 32 neurons the teacher was the constructor's identify-and-plan (made before
# `--teacher-settings`, whose default now plays the task's own settings).
for seed in 0 1; do train n16 "$seed" --task n16 --teacher-settings defaults; done
python $here/table.py > $here/table.md
# Later: the third n16 seed, n32 (three seeds, over three sessions: 87-90 core-minutes a run beside
# other jobs) and every best model on its task's test networks, network by network.
train n16 2 --task n16 --teacher-settings defaults
for seed in 0 1 2; do train n32 "$seed" --task n32 --teacher-settings defaults; done
for trial in "$here"/trials/*/seed=*; do
    size=$(basename "$(dirname "$trial")"); seed=${trial##*=}
    task=$([ "$size" = n8 ] && echo paper || echo "$size")
    spikectl benchmark "$runs/$size-seed$seed" --model best --task "$task" \
        --per-network "$trial/per_network.csv"
done
python $here/table.py > $here/table.md
