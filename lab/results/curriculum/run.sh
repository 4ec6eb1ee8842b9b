#!/usr/bin/env bash
# The runs behind docs/results/curriculum/README.md, from the repository root on the
# project's 2-core AMD EPYC (AVX2), one Torch thread each, two or three at a time.
# A curriculum over sizes: the main job with the proximity input trained at n = 8
# (../proximity-input, runs/proximity/n8-seedS), fine-tuned on the suite's n16 task,
# then that run's best model fine-tuned on n32. The bar is the n = 8 network played at
# 16 and 32 without training (zero-shot). Each run's config.json, metrics.csv and its
# best model's test networks are kept in trials/<stage>/seed=S (weights are not committed).
set -euo pipefail
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
here=docs/results/curriculum
runs=${RUNS:-runs/curriculum}
n8=${N8_RUNS:-runs/proximity}
# The fine-tuning settings of ../curriculum-n32-pilot: a quarter of the main job's steps,
# exploration from 0.1, a quarter of its learning rate; the imitation weight anneals
# from 1 to 0.2 over the first half, against the task's own teacher (the default).
finetune() {  # finetune STAGE TASK SEED SOURCE [FLAGS...]
    local stage=$1 task=$2 seed=$3 source=$4; shift 4
    spikectl train guided --task "$task" --seed "$seed" --init-from "$source" \
        --sizes.inputs target proximity --total-env-steps 66000 --epsilon-start 0.1 \
        --learning-rate 5e-4 --eval-every-episodes 160 "$@" --run-dir "$runs/$stage-seed$seed"
    local out=$here/trials/$stage/seed=$seed
    mkdir -p "$out"
    cp "$runs/$stage-seed$seed/config.json" "$runs/$stage-seed$seed/metrics.csv" "$out/"
    spikectl benchmark "$runs/$stage-seed$seed" --model best --task "$task" \
        --per-network "$out/per_network.csv"
}
# The choice, on seed 0's validation networks: with the imitation loss (kept) or reward only.
finetune n16-imit n16 0 "$n8/n8-seed0"
finetune n16-reward n16 0 "$n8/n8-seed0" --imitation-weight 0 --imitation-weight-end 0
for seed in 1 2; do finetune n16-imit n16 "$seed" "$n8/n8-seed$seed"; done
for seed in 0 1 2; do finetune n32-imit n32 "$seed" "$runs/n16-imit-seed$seed"; done
# The bar: each n = 8 network played at 16 and 32 without training.
mkdir -p "$here/zero-shot"
for seed in 0 1 2; do
    for split in validation test; do
        spikectl benchmark "$n8/n8-seed$seed" --model best --task n16 n32 --split "$split" \
            --per-network "$here/zero-shot/n8-seed$seed-$split.csv"
    done
done
python $here/table.py > $here/table.md
