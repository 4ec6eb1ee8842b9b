#!/usr/bin/env bash
# diagnose_probes.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/confounded-zeros/diagnose_probes.py > diagnose_probes.py
# validation.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/confounded-zeros/validation.py > validation.py
# test.py is retired from the lab (it reads the library's internals; lab/README.md):
#   git show 6a705d8:docs/results/confounded-zeros/test.py > test.py
# The commands of this folder, from the repository root with the package installed.
set -euo pipefail
here=docs/results/confounded-zeros
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
# What a stimulation teaches about the target's column (the named controller, validation).
python $here/diagnose_probes.py paper 100 > $here/diagnose-paper.txt
python $here/diagnose_probes.py n16 20 > $here/diagnose-n16.txt
# The choice: train + validation (n16), the first 70 validation networks (n32), and paper.
for task in paper n16 n32; do
    python $here/validation.py $here $task > $here/validation-$task.txt
done
# The n16 candidate played once on the test set, against the named controller's row.
(cd $here && python test.py .)
python lab/results/bayes-identify/paired_benchmark.py \
    docs/results/bayes-identify/test-benchmark-known-sd-per-network.csv \
    $here/test-n16-per-network.csv --task n16 > $here/test-paired.md
