#!/usr/bin/env bash
# validation.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/hidden-relays/validation.py > validation.py
# The commands of this folder, from the repository root with the package installed.
set -euo pipefail
here=docs/results/hidden-relays
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# Train + validation (the choice), network by network against the controller before.
python $here/validation.py $here > $here/validation-table.txt
# The test set, played once after the choice; against the named controller's row before
# (test-per-network-before.csv: the same command at commit 10fde1b).
spikectl benchmark identify-and-plan --task hidden25 --split test \
    --out $here/test.csv --per-network $here/test-per-network.csv
python lab/results/bayes-identify/paired_benchmark.py \
    $here/test-per-network-before.csv \
    $here/test-per-network.csv --task hidden25 > $here/test-paired.md
