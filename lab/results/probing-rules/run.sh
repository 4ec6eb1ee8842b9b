#!/usr/bin/env bash
# probing_rules.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/probing-rules/probing_rules.py > probing_rules.py
# The commands of this folder, from the repository root with the package installed.
set -euo pipefail
here=docs/results/probing-rules
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
python $here/probing_rules.py paper train 100 idle-quiet-2 idle-quiet-6 imminent-1 imminent-3 dale \
    > $here/paper-train.txt
python $here/probing_rules.py paper validation 100 idle-quiet-2 idle-quiet-6 imminent-1 imminent-3 dale \
    > $here/paper-validation.txt
# About 35 CPU minutes.
python $here/probing_rules.py n16 validation 100 idle-quiet-6 imminent-3 idle-quiet-2 \
    > $here/n16-validation.txt
