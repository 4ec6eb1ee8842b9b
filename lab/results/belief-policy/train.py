"""Train a belief policy (spikectl.agents.belief_policy) by imitation of identify-and-plan's
labels in the episodes ``collect.py`` wrote, on one thread.

    python lab/results/belief-policy/train.py OUT.pt --belief BELIEF.pt DATA.npz \
        [DATA.npz ...] \
        [--epochs 30 --seed 0 --width 64 --labels expert --smoothing 0]

Each episode is replayed through the controller's own belief and feature code (so the
features are those it computes when it acts), then the policy is fitted by cross-entropy
of the label among the legal actions (``--labels expert``: identify-and-plan's;
``--labels rule``: the amortised controller's fixed rule's, read from the features;
Adam, minibatches of one size n). Prints the training loss and the agreement with the
labels per epoch; writes OUT (the belief's and the policy's weights in one file, as
``spikectl.load_controller`` reads it) and OUT.csv (the per-epoch metrics).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.records import write_csv
from spikectl.agents.amortised_controller import load_belief
from spikectl.agents.amortised_kernel import BeliefKernel
from spikectl.agents.belief_policy import (
    N_POLICY_FEATURES,
    NEURON_FEATURES,
    BeliefPolicyController,
    BeliefPolicyNet,
    policy_features,
    save_belief_policy,
)

__all__ = ["fit", "policy_features", "replay"]
from spikectl.neuron import DO_NOTHING


class _Recorder:
    """A policy that scores every action 0 (the features are what is wanted)."""

    def scores(self, features: np.ndarray) -> np.ndarray:
        return np.zeros(features.shape[0] + 1)


def rule_labels(features: np.ndarray) -> np.ndarray:
    """[S] the fixed rule's action (0 nothing, i + 1 neuron i) read from features [S, n, D]."""
    choice = features[:, :, NEURON_FEATURES.index("rule_choice")]  # [S, n]
    return np.where(choice.max(axis=1) > 0, choice.argmax(axis=1) + 1, 0)


def replay(data: dict, belief: BeliefKernel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(features [E * T, n, D], masks [E * T, n + 1], labels [E * T] as indices 0..n)."""
    controller = BeliefPolicyController(belief, _Recorder())
    episodes, steps, n = data["voltage"].shape
    features = np.empty((episodes, steps, n, N_POLICY_FEATURES), dtype=np.float32)
    for e in range(episodes):
        controller.reset()
        for t in range(steps):
            observation = {"voltage": data["voltage"][e, t], "pattern": data["pattern"][e],
                           "target": int(data["target"][e]), "step": int(data["step"][e, t]),
                           "last_action": int(data["last_action"][e, t])}  # fmt: skip
            controller.act(observation, {"action_mask": data["mask"][e, t]})
            features[e, t] = controller.last_features
    labels = data["label"].reshape(-1) - DO_NOTHING
    return features.reshape(-1, n, N_POLICY_FEATURES), data["mask"].reshape(-1, n + 1), labels


def fit(sets: list[tuple[np.ndarray, np.ndarray, np.ndarray]], epochs: int, seed: int,
        width: int, batch: int = 256, learning_rate: float = 1e-3,
        smoothing: float = 0.0) -> tuple[BeliefPolicyNet, list]:  # fmt: skip
    """The policy fitted to every (features, masks, labels) set; per-epoch metrics.
    ``smoothing``: the share of each target spread evenly over the legal actions (so that
    a policy fitted to a deterministic rule still samples other actions)."""
    generator = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    net = BeliefPolicyNet(width)
    optimiser = torch.optim.Adam(net.parameters(), lr=learning_rate)
    tensors = [(torch.from_numpy(f), torch.from_numpy(m), torch.from_numpy(y).long())
               for f, m, y in sets]  # fmt: skip
    rows = []
    for epoch in range(epochs):
        for group in optimiser.param_groups:  # cosine decay to a tenth
            group["lr"] = learning_rate * (0.1 + 0.9 * 0.5 * (1 + np.cos(np.pi * epoch / epochs)))
        order = [(k, index) for k, (f, _, _) in enumerate(tensors)  # minibatches of one n
                 for index in torch.randperm(f.shape[0], generator=generator).split(batch)]
        shuffled = torch.randperm(len(order), generator=generator)
        total, agree, count = 0.0, 0, 0
        for which in shuffled.tolist():
            k, index = order[which]
            features, masks, labels = (tensor[index] for tensor in tensors[k])
            scores = net(features).masked_fill(~masks, -1e9)  # [B, n + 1]
            target = torch.nn.functional.one_hot(labels, masks.shape[1]).float()
            target = (1 - smoothing) * target + smoothing * masks / masks.sum(1, keepdim=True)
            loss = -(target * torch.log_softmax(scores, dim=-1)).sum(dim=-1).mean()
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            total += float(loss.detach()) * labels.shape[0]
            agree += int((scores.argmax(dim=1) == labels).sum())
            count += labels.shape[0]
        rows.append({"epoch": epoch + 1, "loss": total / count, "agreement": agree / count})
        print(rows[-1], flush=True)
    return net.eval(), rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("data", type=Path, nargs="+")
    parser.add_argument("--belief", type=Path, required=True)
    parser.add_argument("--epochs", type=int, default=30)
    parser.add_argument("--width", type=int, default=64)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--labels", choices=("expert", "rule"), default="expert")
    parser.add_argument("--smoothing", type=float, default=0.0)
    arguments = parser.parse_args()
    torch.set_num_threads(1)
    model = load_belief(arguments.belief)
    kernel = BeliefKernel(model)
    by_size: dict[int, list] = {}
    for path in arguments.data:
        data = dict(np.load(path))
        features, masks, labels = replay(data, kernel)
        if arguments.labels == "rule":
            labels = rule_labels(features)
        by_size.setdefault(int(data["n"]), []).append((features, masks, labels))
        print(f"{path}: {data['label'].size} decisions at n = {int(data['n'])}", flush=True)
    sets = [tuple(np.concatenate(parts) for parts in zip(*group, strict=True))
            for group in by_size.values()]  # fmt: skip
    net, rows = fit(sets, arguments.epochs, arguments.seed, arguments.width,
                    smoothing=arguments.smoothing)
    save_belief_policy(model, net, arguments.out)
    write_csv(arguments.out.with_suffix(".csv"), rows)
    print(f"wrote {arguments.out}")


if __name__ == "__main__":
    main()
