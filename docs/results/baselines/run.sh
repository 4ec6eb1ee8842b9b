#!/bin/sh
# The commands that produced the tables of docs/baselines.md (from the repository root,
# 1 thread each, on the project's shared 2-core machine).
set -e
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
out=docs/results/baselines
spikectl baselines --split test --out $out/test_n8.csv | tee $out/test_n8.txt
spikectl baselines --split test --env spikectl/NeuronControlPartial-v0 --out $out/test_partial.csv | tee $out/test_partial.txt
spikectl baselines --split test --env spikectl/NeuronControlNoisy-v0 --out $out/test_noisy2.csv | tee $out/test_noisy2.txt
spikectl baselines --split test --env spikectl/NeuronControl32-v0 --out $out/test_n32.csv | tee $out/test_n32.txt
