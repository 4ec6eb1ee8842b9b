#!/usr/bin/env bash
# Learned rows of suite v2 (docs/benchmark.md, "Suite v2"): a preset trained on one v2
# task (`spikectl train PRESET --task T --suite 2`), its best_model.pt (chosen on the
# task's validation set) scored on the task's 1 000 test networks (its mean in
# benchmark.csv, each network's return in per_network.csv); config.json and metrics.csv
# kept beside them (the weights are not committed). From the repository root, one Torch
# thread per run:
#
#     bash lab/results/suite-v2/train.sh TASK SEED [PRESET [FOLDER [FLAGS...]]]
#
# e.g. the guided preset reading the actions in flight on latency1, seed 0:
#
#     bash lab/results/suite-v2/train.sh latency1 0 guided guided-in-flight \
#         --sizes.inputs target target-voltage actions-in-flight
set -euo pipefail
task=$1 seed=$2 preset=${3:-guided} folder=${4:-${3:-guided}}
shift $(( $# < 4 ? $# : 4 ))
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
run=runs/suite-v2/$folder/$task/seed=$seed
out=docs/results/suite-v2/trained/$folder/$task/seed=$seed
if [ -f "$run/model.pt" ]; then
    :  # trained already
elif [ -d "$run" ]; then
    spikectl train --resume "$run"  # an interrupted run continues where it stopped
else
    spikectl train "$preset" --task "$task" --suite 2 --seed "$seed" "$@" --no-progress \
        --run-dir "$run"
fi
mkdir -p "$out"
cp "$run/config.json" "$run/metrics.csv" "$out/"
spikectl benchmark "$run" --model best --suite 2 --task "$task" --out "$out/benchmark.csv" \
    --per-network "$out/per_network.csv" --overwrite
