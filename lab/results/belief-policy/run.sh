#!/bin/bash
# The belief policy's record (docs/results/belief-policy), from a fresh checkout, one
# thread a process, two processes at a time. Weights and episodes go to $WORK (not
# committed); the CSVs the record shows go to docs/results/belief-policy (evaluate.py,
# times.py, table.py: docs/results/belief-policy/README.md lists them).
set -euo pipefail
WORK=${WORK:-/tmp/belief-policy}
LAB=lab/results/belief-policy
mkdir -p "$WORK"
collect() { python $LAB/collect.py "$@"; }

# The amortised belief (5 000 updates, seed 0: docs/results/amortised-belief).
python lab/results/amortised-belief/train.py --updates 5000 --seed 0 --out "$WORK"

# DAgger round 0: identify-and-plan's own episodes.
collect "$WORK/n16-expert-0.npz" --n 16 --episodes 150 --first 0 &
collect "$WORK/n16-expert-1.npz" --n 16 --episodes 150 --first 150
wait
collect "$WORK/n8-expert-0.npz" --n 8 --episodes 400 --first 0
collect "$WORK/n12-expert-0.npz" --n 12 --episodes 200 --first 0
DATA=("$WORK"/n8-expert-0.npz "$WORK"/n12-expert-0.npz "$WORK"/n16-expert-0.npz "$WORK"/n16-expert-1.npz)
python $LAB/train.py "$WORK/dagger-0.pt" "${DATA[@]}" --belief "$WORK/belief.pt" --epochs 30

# Round 1: round 0's policy, the expert's action on half the steps.
P="--policy $WORK/dagger-0.pt --expert-share 0.5 --seed 1"
collect "$WORK/n16-it1-a.npz" --n 16 --episodes 75 --first 300 $P &
collect "$WORK/n16-it1-b.npz" --n 16 --episodes 75 --first 375 $P
wait
collect "$WORK/n8-it1.npz" --n 8 --episodes 400 --first 400 $P
collect "$WORK/n12-it1.npz" --n 12 --episodes 200 --first 200 $P
DATA+=("$WORK"/n16-it1-a.npz "$WORK"/n16-it1-b.npz "$WORK"/n8-it1.npz "$WORK"/n12-it1.npz)
python $LAB/train.py "$WORK/dagger-1.pt" "${DATA[@]}" --belief "$WORK/belief.pt" --epochs 30

# Round 2: round 1's policy alone.
P="--policy $WORK/dagger-1.pt --expert-share 0 --seed 2"
collect "$WORK/n16-it2-a.npz" --n 16 --episodes 75 --first 450 $P &
collect "$WORK/n16-it2-b.npz" --n 16 --episodes 75 --first 525 $P
wait
collect "$WORK/n8-it2.npz" --n 8 --episodes 800 --first 800 $P
collect "$WORK/n12-it2.npz" --n 12 --episodes 400 --first 400 $P
DATA+=("$WORK"/n16-it2-a.npz "$WORK"/n16-it2-b.npz "$WORK"/n8-it2.npz "$WORK"/n12-it2.npz)
python $LAB/train.py "$WORK/dagger-2.pt" "${DATA[@]}" --belief "$WORK/belief.pt" --epochs 30

# The fixed rule copied (5 % of each target spread over the legal actions), REINFORCE's start.
python $LAB/train.py "$WORK/rule-copy.pt" "${DATA[@]:0:6}" --belief "$WORK/belief.pt" \
    --epochs 15 --labels rule --smoothing 0.05
