#!/usr/bin/env bash
# The learned rows of docs/benchmark.md: the quick preset's TDRQN trained on one suite task
# (`spikectl train quick --task T`), its best_model.pt (chosen on the task's validation set)
# scored on the task's test set (its mean in benchmark.csv, each network's return in
# per_network.csv), and the run's config.json / metrics.csv kept here (the weights are
# not committed). Run from the repository root, one Torch thread per run:
#
#     bash lab/results/suite/train.sh TASK SEED [LEARNER-PRESET [FOLDER [FLAGS...]]]
#
# e.g. `bash lab/results/suite/train.sh stochastic 0`; two at a time on the 2-core machine.
# FOLDER (the preset's name by default) names the folder under runs/suite and trained/:
# the guided preset since the fourth stop of 2026-11-24 (connectivity loss, 24 updates a
# round) is kept under `guided-upr24`, since trained/guided and trained/guided-conn hold
# the runs of the guided presets before it:
#
#     bash lab/results/suite/train.sh hidden25 0 guided guided-upr24 --teacher-settings defaults
#
# (its teacher was the constructor's identify-and-plan on every task: FLAGS, passed on to
# `spikectl train`, say so on every task but `paper`, where the preset's teacher, which
# plays each task's own settings, is the constructor's).
set -euo pipefail
task=$1 seed=$2 preset=${3:-quick} folder=${4:-${3:-quick}}
shift $(( $# < 4 ? $# : 4 ))
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
run=runs/suite/$folder/$task/seed=$seed
out=docs/results/suite/trained/$folder/$task/seed=$seed
if [ -f "$run/model.pt" ]; then
    :  # trained already
elif [ -d "$run" ]; then
    spikectl train --resume "$run"  # an interrupted run continues where it stopped
else
    spikectl train "$preset" --task "$task" --seed "$seed" "$@" --run-dir "$run"
fi
mkdir -p "$out"
cp "$run/config.json" "$run/metrics.csv" "$out/"
spikectl benchmark "$run" --model best --task "$task" --out "$out/benchmark.csv" \
    --per-network "$out/per_network.csv"
