#!/bin/sh
# The commands that produced the tables of docs/baselines.md (from the repository root,
# 1 thread each, on the project's shared 2-core machine, one at a time).
set -e
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
out=docs/results/baselines
# n = 8, the paper's environment
spikectl baselines --split test --out $out/test_n8.csv | tee $out/test_n8.txt
# The curve: measurement noise sigma (mV) x hidden fraction, n = 8 (noise 0, hidden 0
# repeats the line above; noise 2 is NeuronControlNoisy-v0, hidden 0.25
# NeuronControlPartial-v0)
for hidden in 0 0.25; do
  for sigma in 0 1 2 4; do
    spikectl baselines --split test --observation-noise-mV $sigma --hidden-fraction $hidden \
      --out $out/curve_noise${sigma}_hidden${hidden}.csv | tee $out/curve_noise${sigma}_hidden${hidden}.txt
  done
done
# n = 32 (identify-and-plan with beam width 16 to stay under 1 s per episode; oracle width
# 1024: 0.989 on 20 training networks where 256 gave 0.961)
spikectl baselines --split test --env spikectl/NeuronControl32-v0 --identify-width 16 --oracle-width 1024 \
  --out $out/test_n32.csv | tee $out/test_n32.txt
# Why identify-and-plan loses to the oracle (validation networks, not the test set)
python $out/diagnose_identify.py | tee $out/diagnose_identify_n8.txt
python $out/diagnose_identify.py --n-neurons 32 --size 20 --skip-first-action \
  | tee $out/diagnose_identify_n32.txt
python $out/diagnose_identify.py --n-neurons 16 --size 40 --skip-first-action \
  | tee $out/diagnose_identify_n16.txt
# Tables and figure from the CSVs above
python $out/plot_baselines.py $out docs/images/baselines.png
