#!/usr/bin/env bash
# rollout.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/rollout-improvement/rollout.py > rollout.py
# The commands of this folder, from the repository root with the package installed, one
# thread a job, two at a time. Each prints a header line and one return per network
# (collected into per-network.csv); `table.py` prints the table of README.md.
set -euo pipefail
here=docs/results/rollout-improvement
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
# TASK SPLIT NETWORKS K H CANDIDATES [MARGIN] [--base]
python $here/rollout.py paper train 100 4 15 3 --base
python $here/rollout.py paper validation 100 4 15 3 --base
python $here/rollout.py paper validation 100 16 20 3
python $here/rollout.py paper validation 100 8 40 3
python $here/rollout.py paper validation 50 48 20 3 0
python $here/rollout.py paper validation 50 48 20 3 0.01
python $here/rollout.py paper validation 50:100 48 20 3 0.01
python $here/rollout.py paper train 100 48 20 3 0.01
python $here/table.py
