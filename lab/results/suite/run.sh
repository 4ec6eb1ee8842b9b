#!/usr/bin/env bash
# The commands that produced the CSVs of docs/benchmark.md (suite v1, test sets), run from
# the repository root with the package installed. One BLAS / PyTorch thread each. The
# training-free controllers' rows are the same on every CPU kind (their floats do not go
# through NumPy's SIMD maths or BLAS: spikectl/planning/portable.py, tests/test_cpu_kinds.py);
# --overwrite replaces the committed CSVs.
set -euo pipefail
out=docs/results/suite
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
for controller in do-nothing random oracle; do
    spikectl benchmark "$controller" --task all --out "$out/$controller.csv" --overwrite
done
# Identify-and-plan's rows and its return on every test network (the per-network file the
# result tables compare learners with: lab/results/result_tables.py's PLANNER_TEST).
spikectl benchmark identify-and-plan --task all --out "$out/identify-and-plan.csv" \
    --per-network "$out/identify-and-plan-per-network.csv" --overwrite
# (Every row carries decision_p50_ms / decision_p99_ms; the committed rows before those
# columns were given them by: python lab/results/suite/decision_times.py CSV...)
# Identify-and-plan's CPU seconds per episode and per-decision CPU-time percentiles.
python lab/results/bayes-identify/sweep.py --split test --settings '{"named": true}' \
    --tasks paper noise1 noise2 noise4 hidden25 stochastic heterogeneous background n16 n32 \
    --out "$out/identify-and-plan-decision-times.csv"
# Size transfer: the quick preset's TDRQN (trained at n = 8 on the paper's task, runs not
# committed), best_model.pt, zero-shot at n = 8, 16 and 32.
for seed in 0 1 2; do
    spikectl benchmark "runs/quick-this-machine/trials/seed=$seed" --model best \
        --task paper n16 n32 --out "$out/tdrqn-quick-seed$seed.csv"
done
# The same three TDRQNs on every task (transfer from `paper`): runs/suite/quick/paper/seed=S
# is a link to runs/quick-this-machine/trials/seed=S (train.sh paper S made benchmark.csv).
for seed in 0 1 2; do
    spikectl benchmark "runs/suite/quick/paper/seed=$seed" --model best --task all \
        --out "$out/trained/quick/paper/seed=$seed/transfer.csv"
done
# The main job's TDRQNs (`spikectl train guided`, seeds 0-2, trained on `paper`:
# runs/suite/guided/paper/seed=S links to runs/guided-floor20/seed=S, made by
# lab/results/guided_runs.sh guided-floor20 S) on every task.
for seed in 0 1 2; do
    bash lab/results/suite/train.sh paper "$seed" guided
    spikectl benchmark "runs/suite/guided/paper/seed=$seed" --model best --task all \
        --out "$out/trained/guided/paper/seed=$seed/transfer.csv"
done
# A preset's seeds trained on `paper` (runs/suite/PRESET/paper/seed=S, links to the runs of
# lab/results/guided_runs.sh) played on every task: their config, metrics and transfer.csv.
transfer_from_paper() {
    local preset=$1 seed run kept
    for seed in 0 1 2; do
        run=runs/suite/$preset/paper/seed=$seed kept=$out/trained/$preset/paper/seed=$seed
        mkdir -p "$kept"
        cp "$run/config.json" "$run/metrics.csv" "$kept/"
        spikectl benchmark "$run" --model best --task all --out "$kept/transfer.csv"
    done
}
# The main job from the second to the fourth stop of 2026-11-24 (`spikectl train guided`
# with the connectivity loss, 32 updates a round; links to runs/guided-conn01/seed=S) on
# every task, and network by network against identify-and-plan (paired-guided-conn.csv).
transfer_from_paper guided-conn
python lab/results/suite/paired.py --connectivity
# The main job since the fourth stop (the same with 24 updates a round; links to
# runs/guided-upr24/seed=S, made by lab/results/guided_runs.sh guided-upr24 S), and
# network by network (paired-guided-upr24.csv). Its seeds trained on a task itself are
# train.sh's: `bash lab/results/suite/train.sh TASK SEED guided guided-upr24
# --teacher-settings defaults` (the teacher they had; not needed on `paper`).
transfer_from_paper guided-upr24
python lab/results/suite/paired.py --preset guided-upr24
