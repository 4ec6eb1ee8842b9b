#!/usr/bin/env bash
# The runs behind docs/results/advice-input/README.md, from the repository root on the
# project's 2-core AMD EPYC (AVX2), one Torch thread each, at most three at a time.
# Each run's config.json and metrics.csv are copied to trials/<name>/ (weights are not
# committed). RUN_N8_SEED0..2 are the main job without the advice (`spikectl train
# guided --seed S`), and the belief-input runs' validation CSVs are reused from
# ../belief-input/validation/.
set -euo pipefail
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
runs=${RUNS:-runs/advice-input}
here=docs/results/advice-input

# 1. The main job with the planner's advice as an input, seeds 0-2; and seed 0 with the
#    imitation weight annealed to 0 (reward alone at the end).
for seed in 0 1 2; do
    spikectl train guided --sizes.advice-in-input --seed "$seed" --run-dir "$runs/n8-seed$seed"
done
spikectl train guided --sizes.advice-in-input --imitation-weight-end 0 --seed 0 \
    --run-dir "$runs/n8-rl-seed0"
