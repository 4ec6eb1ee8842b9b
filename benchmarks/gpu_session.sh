#!/usr/bin/env bash
# One GPU session (docs/benchmarks.md, "Seed groups on a GPU"), in steps that fit the
# device tool's 10-minute commands; run from the repository root:
#
#   source benchmarks/gpu_session.sh setup   # carried wheels (gymnasium, tyro) + PYTHONPATH
#   bash benchmarks/gpu_session.sh check     # CUDA tests, micro benchmark (Table-2 and quick)
#   bash benchmarks/gpu_session.sh start     # the sweeps below, detached (setsid), as seed groups
#   bash benchmarks/gpu_session.sh protocol  # the paper's protocol instead (below), detached
#   bash benchmarks/gpu_session.sh status    # progress of every trial, GPU use
#   bash benchmarks/gpu_session.sh collect   # results (no checkpoints) -> $OUT/gpu-results.tgz
#
# The sweeps, all at once on one GPU, one process per seed group: the sweep files of
# docs/results/fig4-fast (quick preset, 4 architectures x 5 seeds) and
# docs/results/fig5-quick-n20 (quick, 20 training networks, 3 seeds) with "device": "cuda"
# added to their overrides, and fig4-paper-gpu (Table 2, 4 architectures x 10 seeds, as far
# as the time goes).
#
# `protocol` starts the paper's own protocol at Table 2 (1 M steps a seed) as stacked seed
# groups with CUDA graphs: Figure 4 (4 architectures x 10 seeds, one group per
# architecture) and Figure 5's other sizes (TDRQN on 10, 20 and 40 networks x 10 seeds, one
# group per size; its 100-network point is Figure 4's TDRQN, the same config). Seven
# processes: one group of 30 would stack better on the GPU but steps its 150
# environments on one CPU core, 2.4x slower than a group of 10 (docs/benchmarks.md).
RESULTS=${RESULTS:-/tmp/gpu-results}
OUT=${OUT:-/tmp/gpu-out}
SWEEPS="fig4-fast:4 fig5-quick-n20:1 fig4-paper-gpu:4"

# launch "NAME:WORKERS ..." [FLAG ...]: each sweep $RESULTS/NAME.json as seed groups, detached
# (setsid: they outlive the command), and nvidia-smi's log of GPU use.
launch() {
  nohup nvidia-smi --query-gpu=timestamp,utilization.gpu,memory.used --format=csv -l 15 \
    > "$RESULTS/gpu-use.csv" 2>&1 < /dev/null &
  local entry name
  for entry in $1; do
    name=${entry%%:*}
    setsid nohup python3 -m spikectl.cli sweep --config "$RESULTS/$name.json" \
      --sweep-dir "$RESULTS/$name" --group-seeds "${@:2}" --workers "${entry##*:}" \
      > "$RESULTS/$name.log" 2>&1 < /dev/null &
  done
  sleep 5
}

for step in "$@"; do
  case $step in
    setup)
      python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl || return 1 2>/dev/null || exit 1
      export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
      nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
      python3 -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"
      ;;
    check)
      python3 -m pytest -q -p no:cacheprovider tests/test_ensemble.py -k "cuda or identical" 2>&1 | tail -4
      for preset in paper quick; do
        python3 benchmarks/bench_ensemble.py --micro --preset $preset --device cuda \
          --seeds 1 10 40 | tee "$OUT/micro-$preset-cuda.txt"
      done
      ;;
    start)
      mkdir -p "$RESULTS"
      python3 - "$RESULTS" <<'PY'
import json, pathlib, sys
root = pathlib.Path(sys.argv[1])
for name in ("fig4-fast", "fig5-quick-n20"):
    sweep = json.loads(pathlib.Path(f"docs/results/{name}/sweep-file.json").read_text())
    sweep.setdefault("overrides", {})["device"] = "cuda"
    (root / f"{name}.json").write_text(json.dumps(sweep))
archs = ["drqn", "ddrqn", "dmdrqn", "tdrqn"]
paper = {"base": "paper", "overrides": {"device": "cuda"},
         "grid": {"arch": archs, "seed": list(range(10))}}
(root / "fig4-paper-gpu.json").write_text(json.dumps(paper))
PY
      launch "$SWEEPS"
      ;;
    protocol)
      mkdir -p "$RESULTS"
      python3 - "$RESULTS" <<'PY'
import json, pathlib, sys
root = pathlib.Path(sys.argv[1])
seeds = list(range(10))
sweeps = {
    "fig4-table2": {"arch": ["drqn", "ddrqn", "dmdrqn", "tdrqn"], "seed": seeds},
    **{f"fig5-table2-n{n}": {"arch": ["tdrqn"], "n_train": [n], "seed": seeds}
       for n in (10, 20, 40)},
}
for name, grid in sweeps.items():
    sweep = {"base": "paper", "overrides": {"device": "cuda"}, "grid": grid}
    (root / f"{name}.json").write_text(json.dumps(sweep))
PY
      launch "fig4-table2:4 fig5-table2-n10:1 fig5-table2-n20:1 fig5-table2-n40:1" --stacked
      ;;
    status)
      date -u
      nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader
      for log in "$RESULTS"/*.log; do
        name=$(basename "$log" .log)
        echo "== $name: $(tail -n 2 "$log" | tr '\n' ' ')"
        for metrics in "$RESULTS/$name"/trials/*seed=0/metrics.csv; do  # one seed a group
          [ -f "$metrics" ] && echo "$(basename "$(dirname "$metrics")") $(tail -n 1 "$metrics")"
        done
      done
      ;;
    collect)
      tar -C "$RESULTS" -czf "$OUT/gpu-results.tgz" --exclude='*.pt' --exclude='*.npz' \
        --exclude='tensorboard' --exclude='*.lock' . && ls -la "$OUT"
      ;;
    *) echo "unknown step $step (setup, check, start, protocol, status, collect)"; exit 2 ;;
  esac
done
