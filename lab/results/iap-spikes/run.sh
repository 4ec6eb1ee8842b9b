#!/usr/bin/env bash
# The commands of this folder, from the repository root with the package installed
# (2026-11-30; one thread each, two at a time on a 2-core host).
set -euo pipefail
here=lab/results/iap-spikes data=docs/results/iap-spikes
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# Diagnosis, first 200 validation networks: told the true columns, all or the target's.
python $here/diagnose.py $data 200 > $data/diagnose.txt
# The screen, first 200 validation networks (screen200.csv).
python $here/variants.py $data/screen200.csv 200 no-qmdp named qmdp8-information0.03 \
    qmdp32-information0.03 qmdp16-information0 qmdp16-information0.1 known_sd=0.15 \
    known_sd=0.2 known_sd=0.3 known_sd=0.35 known_sd=0.45 width=64 posterior-sample
# The second look: validation networks 200-599 (second400.csv).
python $here/variants.py $data/second400.csv 200:600 no-qmdp named posterior-sample
# QMDP's own seed (the networks it draws): seeds 1 and 2 on validation networks 0-599.
python $here/variants.py $data/seeds600.csv 600 no-qmdp named-seed1 named-seed2
# The test set, played once with the named controller (QMDP now).
spikectl benchmark identify-and-plan --suite 2 --task spikes-only --out $data/test.csv \
    --per-network $data/test-per-network.csv
# The test row against the named controller before (before-test-per-network.csv, copied
# from docs/results/suite-v2/identify-and-plan-per-network.csv at commit cae9312), doing
# nothing, the oracle and its own paper row.
python $here/compare.py > $data/test.txt
