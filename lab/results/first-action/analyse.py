"""The best first action given the target and the pattern, estimated from returns.csv
(generate.py) and scored on held-out contexts.

    python lab/results/first-action/analyse.py [--mlp]

A quarter of the contexts (permutation seed 0) is held out. The rule learned on the
rest: for each key (the target and the pattern's steps 1..k, the spikes wanted
soonest), the legal first action whose mean return minus the planner's own is highest
on the training contexts with that key (at least 5 of them), taken when that mean
exceeds ``margin``, else the planner's own. Its gain on the held-out contexts is an
unbiased estimate of what that rule adds to identify-and-plan. ``--mlp`` also fits a
small network on the target and the whole pattern (PyTorch, seed 0).
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np
from generate import context  # beside this script

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "first-action"


def load() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(returns [C, 9] by action + 1 (nan: illegal), targets [C], planner's [C] action
    + 1, patterns [C, 60])."""
    with open(HERE / "returns.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    returns = np.array([[float(value) if value else np.nan for value in list(row.values())[3:]]
                        for row in rows])  # fmt: skip
    targets = np.array([int(row["target"]) for row in rows])
    own = np.array([int(row["planner_first_action"]) + 1 for row in rows])
    patterns = np.stack([context(int(row["context"])).pattern for row in rows]).astype(int)
    return returns, targets, own, patterns


def table_rule(gain, keys, train, test, own, margin):
    sums: dict[tuple, np.ndarray] = {}
    counts: dict[tuple, np.ndarray] = {}
    for k in train:
        sums.setdefault(keys[k], np.zeros(9))
        counts.setdefault(keys[k], np.zeros(9))
        sums[keys[k]] += np.nan_to_num(gain[k])
        counts[keys[k]] += ~np.isnan(gain[k])
    choice = own[test].copy()
    for i, k in enumerate(test):
        if keys[k] in sums:
            mean = np.where(counts[keys[k]] >= 5, sums[keys[k]] / np.maximum(counts[keys[k]], 1),
                            -np.inf)  # fmt: skip
            if mean.max() > margin:
                choice[i] = int(np.argmax(mean))
    return choice


def mlp_rule(gain, targets, patterns, train, test):
    import torch

    torch.manual_seed(0)
    features = np.concatenate([np.eye(8)[targets], patterns], axis=1)  # [C, 8 + 60]
    inputs = torch.tensor(features, dtype=torch.float32)
    target_gain = torch.tensor(np.nan_to_num(gain), dtype=torch.float32)
    legal = torch.tensor(~np.isnan(gain), dtype=torch.float32)
    network = torch.nn.Sequential(
        torch.nn.Linear(68, 64), torch.nn.ReLU(),
        torch.nn.Linear(64, 64), torch.nn.ReLU(),
        torch.nn.Linear(64, 9),
    )  # fmt: skip
    optimiser = torch.optim.AdamW(network.parameters(), 1e-3, weight_decay=1e-4)
    rows = torch.tensor(train)
    for _ in range(60):
        for batch in rows[torch.randperm(len(rows))].split(256):
            error = (network(inputs[batch]) - target_gain[batch]) ** 2 * legal[batch]
            loss = error.sum() / legal[batch].sum()
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
    with torch.no_grad():
        predicted = network(inputs[torch.tensor(test)]).numpy()
    predicted[np.isnan(gain[test])] = -np.inf
    return predicted


def main(mlp: bool) -> None:
    returns, targets, own, patterns = load()
    contexts = returns.shape[0]
    planner = returns[np.arange(contexts), own]
    gain = returns - planner[:, None]  # [C, 9]
    print(f"{contexts} contexts: the planner {planner.mean():.3f}, the best first action in "
          f"hindsight {np.nanmax(returns, axis=1).mean():.3f}, the mean over the legal first "
          f"actions {np.nanmean(returns, axis=1).mean():.3f}")  # fmt: skip
    order = np.random.default_rng(0).permutation(contexts)
    train, test = order[: contexts * 3 // 4], order[contexts * 3 // 4 :]
    print("\n| key | margin | keys | held-out contexts changed | gain on them ± se |")
    print("|---|---:|---:|---:|---|")
    for steps in range(8):
        keys = [(int(targets[k]), *patterns[k, 1 : steps + 1].tolist()) for k in range(contexts)]
        for margin in (0.0, 0.005):
            choice = table_rule(gain, keys, train, test, own, margin)
            realised = gain[test, choice]
            print(f"| target + pattern steps 1..{steps} | {margin} | {len(set(keys))} | "
                  f"{np.mean(choice != own[test]):.2f} | {realised.mean():+.4f} ± "
                  f"{realised.std() / np.sqrt(test.size):.4f} |")  # fmt: skip
    if mlp:
        predicted = mlp_rule(gain, targets, patterns, train, test)
        for margin in (0.0, 0.01, 0.02):
            choice = np.where(predicted.max(axis=1) > margin, predicted.argmax(axis=1), own[test])
            realised = gain[test, choice]
            print(f"| MLP on the target and the whole pattern | {margin} | | "
                  f"{np.mean(choice != own[test]):.2f} | {realised.mean():+.4f} ± "
                  f"{realised.std() / np.sqrt(test.size):.4f} |")  # fmt: skip


if __name__ == "__main__":
    main("--mlp" in sys.argv[1:])
