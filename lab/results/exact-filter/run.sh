#!/usr/bin/env bash
# validation.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/exact-filter/validation.py > validation.py
# The commands of this folder, from the repository root with the package installed.
set -euo pipefail
here=docs/results/exact-filter
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# Validation (the choice): before / after, named and told the weights, network by network.
python $here/validation.py $here > $here/validation-table.txt
# Test sets, played once after the choice; against the named controller's rows before.
spikectl benchmark identify-and-plan --task noise1 noise2 noise4 --split test \
    --out $here/test.csv --per-network $here/test-per-network.csv
python lab/results/bayes-identify/paired_benchmark.py \
    docs/results/bayes-identify/test-benchmark-per-network.csv $here/test-per-network.csv \
    --task noise1 noise2 noise4 > $here/test-paired.md
