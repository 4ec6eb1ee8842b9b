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

# round K POLICY SHARE FIRST16 N8 N12: round K's episodes, the policy acting and the
# expert on SHARE of its steps, then the policy fitted on everything so far.
round() {
    local k=$1 policy=$2 share=$3 first=$4 n8=$5 n12=$6
    local acting=(--policy "$policy" --expert-share "$share" --seed "$k")
    collect "$WORK/n16-it$k-a.npz" --n 16 --episodes 75 --first "$first" "${acting[@]}" &
    collect "$WORK/n16-it$k-b.npz" --n 16 --episodes 75 --first $((first + 75)) "${acting[@]}"
    wait
    collect "$WORK/n8-it$k.npz" --n 8 --episodes "$n8" --first "$n8" "${acting[@]}"
    collect "$WORK/n12-it$k.npz" --n 12 --episodes "$n12" --first "$n12" "${acting[@]}"
    DATA+=("$WORK/n16-it$k-a.npz" "$WORK/n16-it$k-b.npz" "$WORK/n8-it$k.npz" "$WORK/n12-it$k.npz")
    python $LAB/train.py "$WORK/dagger-$k.pt" "${DATA[@]}" --belief "$WORK/belief.pt" --epochs 30
}
round 1 "$WORK/dagger-0.pt" 0.5 300 400 200   # round 0's policy, the expert on half the steps
round 2 "$WORK/dagger-1.pt" 0 450 800 400     # round 1's policy alone

# The fixed rule copied (5 % of each target spread over the legal actions), REINFORCE's start.
python $LAB/train.py "$WORK/rule-copy.pt" "${DATA[@]:0:6}" --belief "$WORK/belief.pt" \
    --epochs 15 --labels rule --smoothing 0.05
