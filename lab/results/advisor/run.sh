#!/usr/bin/env bash
# advisor.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/advisor/advisor.py > advisor.py
# benchmark.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/advisor/benchmark.py > benchmark.py
# The runs behind docs/results/advisor/README.md, from the repository root on the
# project's 2-core AMD EPYC (AVX2), one Torch thread each, two to four at a time. Each
# run's config.json and metrics.csv are copied to trials/NAME/ (weights are not
# committed); table.py prints the tables of README.md.
set -euo pipefail
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
here=docs/results/advisor
runs=${RUNS:-runs/advisor}
advisor() {  # advisor NAME SEED ALPHA TEACHER IMITATION_END
    local name=$1; shift
    python $here/advisor.py "$runs/$name" "$@"
    mkdir -p "$here/trials/$name"
    cp "$runs/$name/config.json" "$runs/$name/metrics.csv" "$here/trials/$name/"
}
advisor identify-a4-end1-seed0 0 4 identify 1.0
advisor identify-a0-end1-seed0 0 0 identify 1.0
advisor told-weights-a4-end1-seed0 0 4 told-weights 1.0
python $here/table.py > $here/table.md
# Later (2026-11-28): alpha 4 with the realisable teacher at seeds 1 and 2, and each seed's
# best model on the paper task's test networks, network by network.
for seed in 1 2; do advisor "identify-a4-end1-seed$seed" "$seed" 4 identify 1.0; done
for seed in 0 1 2; do
    python $here/benchmark.py "$runs/identify-a4-end1-seed$seed" \
        "$here/trials/identify-a4-end1-seed$seed/per_network.csv"
done
python $here/table.py > $here/table.md
