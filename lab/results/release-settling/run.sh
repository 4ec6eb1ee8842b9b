#!/usr/bin/env bash
# The commands of this folder, from the repository root with the package installed.
set -euo pipefail
here=docs/results/release-settling
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# Train + validation (the choice), network by network against the release chance.
python $here/validation.py $here > $here/validation-table.txt
# The test set, played once after the choice; against the named controller's row before.
spikectl benchmark identify-and-plan --task stochastic --split test \
    --out $here/test.csv --per-network $here/test-per-network.csv
python lab/results/bayes-identify/paired_benchmark.py \
    docs/results/bayes-identify/test-benchmark-known-sd-per-network.csv \
    $here/test-per-network.csv --task stochastic > $here/test-paired.md
