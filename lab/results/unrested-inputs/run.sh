#!/usr/bin/env bash
# validation.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/unrested-inputs/validation.py > validation.py
# The commands of this folder, from the repository root with the package installed.
set -euo pipefail
here=docs/results/unrested-inputs
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# Train + validation (the choice), network by network against the plan's action.
python $here/validation.py $here > $here/validation-table.txt
# The test set, played once after the choice; against the named controller's row before.
spikectl benchmark identify-and-plan --task stochastic --split test \
    --out $here/test.csv --per-network $here/test-per-network.csv
python lab/results/bayes-identify/paired_benchmark.py \
    docs/results/release-settling/test-per-network.csv \
    $here/test-per-network.csv --task stochastic > $here/test-paired.md
