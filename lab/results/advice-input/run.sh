#!/usr/bin/env bash
# agreement.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/advice-input/agreement.py > agreement.py
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

# 2. Every suite task on its validation set, network by network (n32 by seed 0 only: the
#    planner's QMDP costs ~20 CPU minutes there), against identify-and-plan's run of
#    ../belief-input/.
bench() {  # bench NAME RUN TASKS...
    local name=$1 run=$2; shift 2
    spikectl benchmark "$run" --task "$@" --split validation \
        --out "$here/validation/$name-val.csv" --per-network "$here/validation/$name-val-per-network.csv"
}
bench advice-s0 "$runs/n8-seed0" all
for seed in 1 2; do
    bench "advice-s$seed" "$runs/n8-seed$seed" paper n16 noise1 noise2 noise4 hidden25 \
        stochastic heterogeneous background
done
python lab/results/belief-input/compare.py \
    --old docs/results/belief-input/validation/identify-and-plan-val.csv \
    --new $here/validation/advice-s{0,1,2}-val.csv \
    --names "identify-and-plan" "with advice" > $here/validation.md

# 3. How often each run does what its advice says (validation).
{ python $here/agreement.py --task paper --run "$runs/n8-seed0" --count 25
  python $here/agreement.py --task n16 --run "$runs/n8-seed0" --count 25; } > $here/agreement.txt
python $here/agreement.py --task paper --run "$runs/n8-rl-seed0" --count 100 \
    > $here/agreement-reward-alone.txt
