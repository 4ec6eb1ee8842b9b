#!/usr/bin/env bash
# The commands of this folder, from the repository root with the package installed
# (2026-11-29; one thread, nice -n 5, on a 2-core host shared with two trainings).
set -euo pipefail
here=lab/results/iap-rig data=docs/results/iap-rig
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# The rig composition, validation networks 0-199 (validation200.csv).
python $here/variants.py $data/validation200.csv 200 named
# The screen, first 100 validation networks (screen100.csv).
python $here/variants.py $data/screen100.csv 100 named miss=0.01 scale=4 scale=0.2 \
    known_sd=0.15 known_sd=0.35
# Diagnosis, first 100 validation networks: told the true columns, without background.
python $here/diagnose.py $data 100 > $data/diagnose.txt
# The same, told the target's column alone (2026-11-30, AMD EPYC; diagnose-target.txt).
python $here/diagnose.py $data 100 target > $data/diagnose-target.txt
# The second look: validation networks 200-399.
python $here/variants.py $data/validation200.csv 200:400 named
# The test set, played once with the rig composition (the named controller now).
python $here/play_test_row.py $data/test > $data/test.txt
# Planning on K networks drawn from the posterior (2026-11-30, AMD EPYC; the rows of
# screen100.csv; "named" is the composition planning on the estimate alone).
python $here/variants.py $data/screen100.csv 100 hypotheses=4 hypotheses=8 \
    hypotheses=8,seed=1 known-only
# The second look at hypotheses=8: validation networks 200-399, in two parts (one a core).
python $here/variants.py $data/validation200.csv 200:300 hypotheses=8
python $here/variants.py $data/validation200.csv 300:400 hypotheses=8
# The test set, played once with the rig composition planning on 8 networks, in two
# parts (one a core; the same returns as one run), then the rows.
python $here/play_test_row.py $data/test-hypotheses 0:500
python $here/play_test_row.py $data/test-hypotheses 500:1000
python $here/play_test_row.py $data/test-hypotheses --merge > $data/test-hypotheses.txt
# After the test run: 16 networks on the first 100 validation networks (screen100.csv).
python $here/variants.py $data/screen100.csv 100 hypotheses=16
# After the test run: the draws of seed 2, in two parts of 50 (one a core).
python $here/variants.py $data/screen100.csv 0:50 hypotheses=8,seed=2
python $here/variants.py $data/screen100.csv 50:100 hypotheses=8,seed=2
