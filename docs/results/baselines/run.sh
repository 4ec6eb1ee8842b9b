#!/bin/sh
# The commands that produced the tables of docs/baselines.md (from the repository root,
# 1 thread each, on the project's shared 2-core machine, one at a time).
set -e
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
out=docs/results/baselines
# n = 8, the paper's environment, and the registered variants
spikectl baselines --split test --out $out/test_n8.csv | tee $out/test_n8.txt
spikectl baselines --split test --env spikectl/NeuronControlPartial-v0 --out $out/test_partial.csv | tee $out/test_partial.txt
spikectl baselines --split test --env spikectl/NeuronControlNoisy-v0 --out $out/test_noisy2.csv | tee $out/test_noisy2.txt
# The curve: measurement noise sigma (mV) x hidden fraction, n = 8
for hidden in 0 0.25; do
  for sigma in 0 1 2 4; do
    spikectl baselines --split test --observation-noise-mV $sigma --hidden-fraction $hidden \
      --out $out/curve_noise${sigma}_hidden${hidden}.csv | tee $out/curve_noise${sigma}_hidden${hidden}.txt
  done
done
# n = 32
spikectl baselines --split test --env spikectl/NeuronControl32-v0 --out $out/test_n32.csv | tee $out/test_n32.txt
