#!/usr/bin/env bash
# The runs behind docs/results/particles/README.md, from the repository root on the
# project's 2-core AMD EPYC (AVX2), one BLAS thread, beside one or two other jobs: the
# particle posterior (IdentifyAndPlan(identification="particles")) on the n16 and n32
# validation networks in the three forms the Gaussian estimate was measured in
# (../bayes-identify: sweeps 12, 9 and 11); the choice (the named controller at 32
# neurons, spikectl.planning.policy.PARTICLES_FROM_NEURONS) checked on the first 100
# n32 training networks, then the n32 test set played once; then the table.
set -euo pipefail
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
here=docs/results/particles
sweep=lab/results/bayes-identify/sweep.py
P='"identification": "particles"'
python $sweep --tasks n16 --split validation \
    --settings "{$P, \"known_sd\": 0.4}" "{$P}" "{$P, \"known_sd\": 0.3}" \
    --out $here/validation-n16.csv --per-network $here/validation-n16-per-network.csv
python $sweep --tasks n32 --split validation --settings "{$P, \"known_sd\": 0.4}" "{$P}" \
    --out $here/validation-n32.csv --per-network $here/validation-n32-per-network.csv
python $sweep --tasks n16 --split validation --settings "{\"named\": true, $P}" \
    --out $here/validation-named-n16.csv --per-network $here/validation-named-n16-per-network.csv
python $sweep --tasks n32 --split validation --settings "{\"named\": true, $P}" \
    --out $here/validation-named-n32.csv --per-network $here/validation-named-n32-per-network.csv
# The check on training networks, both settings in one run (the rows were written two
# processes side by side and joined; "named" played the Gaussian estimate then).
python $sweep --tasks n32 --split train \
    --settings '{"named": true, "identification": "gaussian"}' "{\"named\": true, $P}" \
    --out $here/train-n32.csv --per-network $here/train-n32-per-network.csv
# The test set, once, as `spikectl benchmark` plays it now; test-before-per-network.csv
# holds the n32 rows of ../bayes-identify/test-benchmark-known-sd-per-network.csv (the
# named controller before, the Gaussian estimate).
spikectl benchmark identify-and-plan --task n32 --out $here/test.csv \
    --per-network $here/test-per-network.csv
# The fast form's CPU time against the Gaussian estimate's, both in one run.
python $sweep --tasks n16 n32 --split validation --size 30 \
    --settings '{"known_sd": 0.4}' "{$P, \"known_sd\": 0.4}" --out $here/timing-fast-form.csv
python $here/table.py > $here/table.md
