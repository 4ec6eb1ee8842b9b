#!/usr/bin/env bash
# teacher_cost.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/task-teacher/teacher_cost.py > teacher_cost.py
# The runs behind docs/results/task-teacher/README.md, from the repository root on the
# project's 2-core AMD EPYC (AVX2), one Torch thread each, beside one other training run.
# The main job trained on `heterogeneous` with its teacher playing the task's own settings
# (`--teacher-settings task`, the default): identify-and-plan's extensions, each neuron's
# threshold and leak learned. The runs it is compared with are the suite's
# (../suite/trained/guided-upr24/heterogeneous/, the same command with
# `--teacher-settings defaults`). Each run's config.json, metrics.csv and its best
# model's test networks, network by network, are kept in trials/heterogeneous/seed=S.
set -euo pipefail
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
here=docs/results/task-teacher
runs=${RUNS:-runs/task-teacher}
train() {  # train TASK SEED: the main job on TASK with the task's teacher, then its test
    local task=$1 seed=$2
    local run=$runs/$task/seed=$seed out=$here/trials/$task/seed=$seed
    spikectl train guided --task "$task" --seed "$seed" --run-dir "$run"
    mkdir -p "$out"
    cp "$run/config.json" "$run/metrics.csv" "$out/"
    spikectl benchmark "$run" --model best --task "$task" --out "$out/benchmark.csv" \
        --per-network "$out/per_network.csv"
}
for seed in 0 1 2; do train heterogeneous "$seed"; done
# At 16 neurons, seeds 0, 1 and 2 (later sessions; seed 2 was stopped and resumed with
# `spikectl train --resume runs/task-teacher/n16/seed=2`); the same comparison.
for seed in 0 1 2; do train n16 "$seed"; done
python $here/teacher_cost.py > $here/teacher-cost.md
python $here/table.py > $here/table.md
