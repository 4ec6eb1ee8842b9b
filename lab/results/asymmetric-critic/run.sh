#!/usr/bin/env bash
# update_cost.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/asymmetric-critic/update_cost.py > update_cost.py
# The runs behind docs/results/asymmetric-critic/README.md, from the repository root on
# the project's 2-core AMD EPYC (AVX2), one Torch thread each, beside two or three other
# jobs: the README's main job with the privileged critic (`--asymmetric-critic`), seeds
# 0-2, each run's config.json and metrics.csv copied to trials/seed=S and its best model
# played on the paper task's 100 test networks, network by network. The runs it is
# compared with are the main job's committed seeds (../guided-ntrain1000/trials).
set -euo pipefail
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
here=docs/results/asymmetric-critic
runs=${RUNS:-runs/asymmetric}
for seed in 0 1 2; do
    run=$runs/seed=$seed out=$here/trials/seed=$seed
    spikectl train guided --asymmetric-critic --seed "$seed" --run-dir "$run"
    mkdir -p "$out"
    cp "$run/config.json" "$run/metrics.csv" "$out/"
    spikectl benchmark "$run" --model best --task paper --out "$out/benchmark.csv" \
        --per-network "$out/per_network.csv"
done
python $here/table.py > $here/table.md
python $here/update_cost.py  # update-cost.txt
