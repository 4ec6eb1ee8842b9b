#!/usr/bin/env bash
# validation.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/filter-margin/validation.py > validation.py
# The commands of this folder, from the repository root with the package installed.
set -euo pipefail
here=docs/results/filter-margin
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# Train + validation (the choice), network by network against the paper's threshold.
python $here/validation.py $here > $here/validation-table.txt
# The test sets, played once after the choice; against the named controller's rows before.
spikectl benchmark identify-and-plan --task noise1 noise2 noise4 --split test \
    --out $here/test.csv --per-network $here/test-per-network.csv
python lab/results/bayes-identify/paired_benchmark.py \
    docs/results/exact-filter/test-per-network.csv $here/test-per-network.csv \
    --task noise1 noise2 noise4 > $here/test-paired.md
