#!/usr/bin/env bash
# do_nothing_bias.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/belief-input/do_nothing_bias.py > do_nothing_bias.py
# The runs behind docs/results/belief-input/README.md, from the repository root on the
# project's 2-core AMD EPYC (AVX2), one Torch thread each, at most three at a time.
# Each run's config.json and metrics.csv are copied to trials/<name>/ (weights are not
# committed); the benchmark CSVs name each controller by its run (belief-seedS,
# main-job-seedS) instead of its path. RUN_N8_SEED0..2 are the main job without the belief (`spikectl train
# guided --seed S`), for the comparison.
set -euo pipefail
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
runs=${RUNS:-runs/belief-input}

# 1. The main job with the belief input, seeds 0-2.
for seed in 0 1 2; do
    spikectl train guided --sizes.belief-in-input --seed "$seed" --run-dir "$runs/n8-seed$seed"
done

# 2. Every suite task on its validation set, network by network: these runs, the main
#    job without the belief, and identify-and-plan.
here=docs/results/belief-input
bench() {  # bench NAME CONTROLLER
    spikectl benchmark "$2" --task all --split validation \
        --out "$here/validation/$1-val.csv" --per-network "$here/validation/$1-val-per-network.csv"
}
for seed in 0 1 2; do bench "belief-s$seed" "$runs/n8-seed$seed"; done
bench main-s0 "$RUN_N8_SEED0"; bench main-s1 "$RUN_N8_SEED1"; bench main-s2 "$RUN_N8_SEED2"
bench identify-and-plan identify-and-plan
python $here/compare.py \
    --old $here/validation/main-s{0,1,2}-val.csv --new $here/validation/belief-s{0,1,2}-val.csv \
    --reference $here/validation/identify-and-plan-val.csv \
    --names "main job" "with belief" "identify-and-plan" > $here/validation.md

# 3. Fine-tuned at 32 neurons from seed 0 (as ../curriculum-n32-pilot/ without the
#    belief): with the teacher, and by reward alone.
ft=(--task n32 --seed 0 --init-from "$runs/n8-seed0" --sizes.belief-in-input --teacher-settings defaults
    --total-env-steps 66000 --epsilon-start 0.1 --learning-rate 5e-4 --eval-every-episodes 160)
spikectl train guided "${ft[@]}" --run-dir "$runs/n32-ft-seed0"
spikectl train guided "${ft[@]}" --imitation-weight 0 --imitation-weight-end 0 \
    --run-dir "$runs/n32-rl-seed0"

# 4. Where the student with the belief loses to its teacher (the planner beside it).
python lab/results/student-n32-diagnosis/diagnose.py --task paper \
    --run "$runs/n8-seed1" --run "$runs/n8-seed2" > $here/diagnose-paper.txt
python lab/results/student-n32-diagnosis/diagnose.py --task n32 \
    --run "$runs/n8-seed1:32" --run "$runs/n32-ft-seed0" > $here/diagnose-n32.txt

# 5. The do-nothing value lowered by delta at play time (no retraining); RUN_N8_SEEDS are
#    the main job's seeds without the belief.
r8=(--run "$runs/n8-seed0" --run "$runs/n8-seed1" --run "$runs/n8-seed2"
    --run "$RUN_N8_SEED0" --run "$RUN_N8_SEED1" --run "$RUN_N8_SEED2")
r32=(); for ((i = 1; i < ${#r8[@]}; i += 2)); do r32+=(--run "${r8[i]}:32"); done
{
    python $here/do_nothing_bias.py --task paper "${r8[@]}" --delta 0 0.01 0.02 0.03 0.04 0.05 0.07
    echo
    python $here/do_nothing_bias.py --task n32 "${r32[@]}" --delta 0 0.01 0.02 0.03 0.05 0.07 0.1
} > $here/do-nothing-bias.txt
