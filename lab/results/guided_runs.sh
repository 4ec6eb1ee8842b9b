#!/usr/bin/env bash
# The commands behind the 2026-11-24 rows of docs/training.md's guided-learner table (and
# the PQN row), run from the repository root on the project's 2-core AMD EPYC, one Torch
# thread each, two at a time. Each run's config.json and metrics.csv are committed under
# docs/results/<folder>/trials/seed=S (the weights are not):
#
#     bash lab/results/guided_runs.sh FOLDER SEED
#
# then copy RUN/{config.json,metrics.csv,baselines.json,machine.json} into
# docs/results/FOLDER/trials/seed=SEED and redraw with guided_table.py / plot_guided.py.
set -euo pipefail
folder=$1 seed=$2
u32=(--updates-per-round 32)
n100=(--n-train 100)
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
case $folder in
    # Each command pins the settings that differ from the guided preset of the day. The
    # preset had the imitation floor 0.2 from 2026-11-24, the connectivity loss (0.1)
    # from the second stop of that day and 24 updates a round from the fourth; the rows
    # made before pin them off (`${u32[@]}`: the 32 updates a round of those rows). It
    # trains on 1 000 networks from 2026-11-25's second session: the rows made before
    # pin the 100 of their day (`${n100[@]}`).
    guided-compiled)      flags=("${n100[@]}" "${u32[@]}" --connectivity-weight 0 --imitation-weight-end 0) ;;   # the pre-2026-11-24 preset
    guided-mix50)         flags=("${n100[@]}" "${u32[@]}" --connectivity-weight 0 --imitation-weight-end 0 --teacher-episodes 0.5) ;;
    guided-floor20)       flags=("${n100[@]}" "${u32[@]}" --connectivity-weight 0) ;;
    guided-floor20-mix50) flags=("${n100[@]}" "${u32[@]}" --connectivity-weight 0 --teacher-episodes 0.5) ;;
    guided-floor50)       flags=("${n100[@]}" "${u32[@]}" --connectivity-weight 0 --imitation-weight-end 0.5) ;;
    # Four times the environment steps (about 60 core-minutes, issue 23's budget).
    guided-floor20-mix50-4x) flags=("${n100[@]}" "${u32[@]}" --connectivity-weight 0 --teacher-episodes 0.5 --total-env-steps 1056000) ;;
    # The privileged connectivity loss (2026-11-24, second stop of the day).
    guided-conn01)        flags=("${n100[@]}" "${u32[@]}") ;;  # the guided preset of the second and third stops
    guided-conn1)         flags=("${n100[@]}" "${u32[@]}" --connectivity-weight 1) ;;
    guided-conn01-4x)     flags=("${n100[@]}" "${u32[@]}" --total-env-steps 1056000) ;;
    # Fewer gradient updates per round, to fit the main job in 15 core-minutes (2026-11-24,
    # fourth stop of the day; chosen on validation). Its seeds run again on an AMD EPYC
    # with AVX-512 (2026-11-25) are kept in docs/results/guided-upr24-avx512.
    guided-upr24)         flags=("${n100[@]}" --updates-per-round 24) ;;
    guided-upr28)         flags=("${n100[@]}" --updates-per-round 28) ;;
    # Each neuron's memory told how many other neurons show a spike (2026-11-25).
    guided-others)        flags=("${n100[@]}" --sizes.inputs target target-voltage others-spiking) ;;
    # Ten times the training networks (2026-11-25, second session; the main job since):
    # on 100 the learner scored 0.84-0.86 on its training networks, 0.81-0.82 on validation.
    guided-ntrain1000)    flags=() ;;  # the main job since then
    # ... and 4x the steps on 4000 networks (each seen as often as 1000 at 1x),
    # evaluated every 800 episodes: issue 23's 60 core-minutes.
    guided-ntrain4000-4x) flags=(--n-train 4000 --total-env-steps 1056000 --eval-every-episodes 800) ;;
    # A wider memory: each neuron's LSTM 128 wide instead of 64 (pilot, 2026-11-25).
    guided-lstm128)       flags=(--sizes.lstm-hidden 128) ;;
    pqn)                  exec spikectl train pqn --seed "$seed" --run-dir "runs/$folder/seed=$seed" ;;
    *) echo "unknown folder $folder" >&2; exit 2 ;;
esac
spikectl train guided "${flags[@]}" --seed "$seed" --run-dir "runs/$folder/seed=$seed"
