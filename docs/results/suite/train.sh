#!/usr/bin/env bash
# The learned rows of docs/benchmark.md: the quick preset's TDRQN trained on one suite task
# (`spikectl train quick --task T`), its best_model.pt (chosen on the task's validation set)
# scored on the task's test set, and the run's config.json / metrics.csv kept here (the
# weights are not committed). Run from the repository root, one Torch thread per run:
#
#     bash docs/results/suite/train.sh TASK SEED [LEARNER-PRESET]
#
# e.g. `bash docs/results/suite/train.sh stochastic 0`; two at a time on the 2-core machine.
set -euo pipefail
task=$1 seed=$2 preset=${3:-quick}
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
run=runs/suite/$preset/$task/seed=$seed
out=docs/results/suite/trained/$preset/$task/seed=$seed
if [ -f "$run/model.pt" ]; then
    :  # trained already
elif [ -d "$run" ]; then
    spikectl train --resume "$run"  # an interrupted run continues where it stopped
else
    spikectl train "$preset" --task "$task" --seed "$seed" --run-dir "$run"
fi
mkdir -p "$out"
cp "$run/config.json" "$run/metrics.csv" "$out/"
spikectl benchmark "$run" --model best --task "$task" --out "$out/benchmark.csv"
