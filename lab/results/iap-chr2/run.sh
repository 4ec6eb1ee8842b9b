#!/usr/bin/env bash
# The commands of this folder, from the repository root with the package installed
# (2026-11-29; one thread, nice -n 5, on a 2-core host shared with two trainings).
set -euo pipefail
here=lab/results/iap-chr2 data=docs/results/iap-chr2
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# Diagnosis, first 50 validation networks: the named controller as it was, the exact
# posterior, told the true weights, the oracle; the paper task's for comparison.
python $here/diagnose.py $data 50 chr2 > $data/diagnose-chr2.txt
python $here/diagnose.py $data 50 paper > $data/diagnose-paper.txt
# The screen, first 50 validation networks (screen50.csv; "ready-at-drive" was played
# with ready-at-drive.diff applied to spikectl/planning/policy.py, as "named").
python $here/variants.py $data/screen50.csv 50 named known_sd=0.35 known_sd=0.45 \
    kind=bayes width=64 horizon=30 horizon=None kind=bayes,known_sd=0.35 never-probe \
    least-likely-first sampled-inputs=8
# The choice: validation networks 0-199, then 200-399 as a second look.
python $here/variants.py $data/validation200.csv 200 named kind=bayes
python $here/variants.py $data/validation200.csv 200:400 named kind=bayes
# The test set, played once with the chr2 composition (the named controller now).
python $here/play_test_row.py $data/test
# A lead (2026-11-30, AMD EPYC): the chr2 composition planning on 8 networks drawn from
# its posterior, as the rig composition does (screen50.csv, then validation200.csv 0-199).
python $here/variants.py $data/screen50.csv 50 kind=bayes,hypotheses=8
python $here/variants.py $data/validation200.csv 200 kind=bayes,hypotheses=8
