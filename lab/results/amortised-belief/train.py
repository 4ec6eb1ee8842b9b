"""Train the amortised belief (issue 61) on one core and save it beside its metrics.

    python lab/results/amortised-belief/train.py --updates 6000 --seed 0 \
        --out docs/results/amortised-belief

Writes OUT/config.json, OUT/train_metrics.csv and OUT/belief.pt (the state dict).
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import torch

from spikectl.training.belief import BeliefTrainingConfig, train_belief


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--updates", type=int, default=6000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("docs/results/amortised-belief"))
    arguments = parser.parse_args()
    torch.set_num_threads(1)
    config = BeliefTrainingConfig(seed=arguments.seed, updates=arguments.updates)
    model, rows = train_belief(config)
    arguments.out.mkdir(parents=True, exist_ok=True)
    (arguments.out / "config.json").write_text(json.dumps(config.to_dict(), indent=2) + "\n")
    with open(arguments.out / "train_metrics.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    torch.save(model.state_dict(), arguments.out / "belief.pt")
    print(rows[-1])


if __name__ == "__main__":
    main()
