"""Fine-tune the amortised belief on a behaviour mix that holds the planner's and the
learner's own episodes beside the random probes it was trained on (issue 61, item 1).

    python lab/results/amortised-belief/finetune.py OUT.pt --belief BELIEF.pt \
        --episodes FILE.npz [FILE.npz ...] [--updates 1500 --share 0.5 --seed 0]

Each update takes, with probability ``--share``, 16 stored episodes of one file
(``lab/results/belief-policy/collect.py``'s: identify-and-plan acting, or a belief policy
acting; read as ``reliability.planner_batch`` reads them), else 16 fresh episodes of the
training mix (``BehaviourMix()``, a size among 8, 12, 16, 24, 32), and takes one Adam
step on the belief's training loss (``belief_loss``) at the training run's final
learning rate. Writes OUT (the state dict) and OUT.csv (the mean loss per 100 updates).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.records import write_csv
from spikectl import NeuronParams
from spikectl.agents.amortised_controller import load_belief
from spikectl.training.belief import BeliefTrainingConfig, belief_loss
from spikectl.training.belief_episodes import BehaviourMix, BeliefBatch, belief_batch

_spec = importlib.util.spec_from_file_location("reliability",
                                               Path(__file__).with_name("reliability.py"))
reliability = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(reliability)

BATCH = 16


def part(batch: BeliefBatch, index: np.ndarray) -> BeliefBatch:
    """The episodes ``index`` of a batch."""
    return BeliefBatch(*(field[index] for field in batch))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--belief", type=Path, required=True)
    parser.add_argument("--episodes", type=Path, nargs="+", required=True)
    parser.add_argument("--updates", type=int, default=1500)
    parser.add_argument("--share", type=float, default=0.5)
    parser.add_argument("--seed", type=int, default=0)
    arguments = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(arguments.seed)
    model, params = load_belief(arguments.belief), NeuronParams()
    stored = [reliability.planner_batch(path, params) for path in arguments.episodes]
    config = BeliefTrainingConfig()
    optimiser = torch.optim.Adam(model.parameters(), lr=config.final_learning_rate)
    rng = np.random.default_rng([arguments.seed, 61])
    model.train()
    rows, running, count, started = [], 0.0, 0, time.process_time()
    for update in range(1, arguments.updates + 1):
        if rng.random() < arguments.share:
            source = stored[int(rng.integers(len(stored)))]
            batch = part(source, rng.choice(source.features.shape[0], BATCH, replace=False))
        else:
            n = int(rng.choice(config.sizes))
            batch = belief_batch(rng, n, BATCH, config.episode_length, BehaviourMix())
        features = torch.from_numpy(batch.features)  # [B, T, n, F]
        loss = belief_loss(model(features), torch.from_numpy(batch.labels),
                           torch.from_numpy(batch.is_target))  # fmt: skip
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        running, count = running + loss.item(), count + 1
        if update % 100 == 0 or update == arguments.updates:
            rows.append({"update": update, "train_loss": running / count,
                         "cpu_seconds": round(time.process_time() - started, 1)})  # fmt: skip
            print(rows[-1], flush=True)
            running, count = 0.0, 0
    torch.save(model.eval().state_dict(), arguments.out)
    write_csv(arguments.out.with_suffix(".csv"), rows)
    print(f"wrote {arguments.out}")


if __name__ == "__main__":
    main()
