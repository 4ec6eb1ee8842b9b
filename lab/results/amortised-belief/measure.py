"""Measure the amortised belief on held-out networks (issue 61, item 1).

    python lab/results/amortised-belief/measure.py --run docs/results/amortised-belief \
        > docs/results/amortised-belief/measure.txt

For each size n and behaviour, ``--episodes`` held-out episodes (networks drawn from
``default_rng([HELD_OUT_SEED, n, behaviour index])``, a stream training never draws)
are scored after k steps: the binary cross-entropy of "neuron i has a synapse onto the
target" (nats per neuron, the target excluded) of

- ``amortised``: the trained belief,
- ``gaussian``: identify-and-plan's default estimate (``ConnectivityEstimate``, its
  ridge regression, read through ``entry_probabilities``), fed the same observations,
- ``exact``: the exact posterior over {-1, 0, +1} per column
  (``DiscreteConnectivityEstimate``; n <= 11 only),
- ``particles``: its particle form (``ParticleConnectivityEstimate``; with --particles),

against the base rate (the generator's prior by distance: no evidence), and the mean
over every step 1..60 (how the TDRQN connectivity head's 28 % was measured). Writes
RUN/scores.csv and prints the table and the belief's step times.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path

import numpy as np
import torch

from spikectl import NeuronParams
from spikectl.agents.amortised_belief import AmortisedBelief
from spikectl.planning import (
    ConnectivityEstimate,
    DiscreteConnectivityEstimate,
    ObservedState,
    ParticleConnectivityEstimate,
)
from spikectl.training.belief import belief_scores, synapse_probabilities
from spikectl.training.belief_episodes import BehaviourMix, BeliefBatch, belief_batch

HELD_OUT_SEED = 61_000
AFTER_STEPS = (1, 10, 25, 50, 60)
NOISE_FREE_RESIDUAL_SD = 0.01  # identify-and-plan's assumption without measurement noise
BEHAVIOURS = {
    "mix": BehaviourMix(),  # the training mix
    "half": BehaviourMix(min_rate=0.5, max_rate=0.5, stretch_probability=0.0),
}


def load(run: Path) -> AmortisedBelief:
    config = json.loads((run / "config.json").read_text())
    model = AmortisedBelief(config["width"], config["heads"], config["mix_layers"])
    model.load_state_dict(torch.load(run / "belief.pt", weights_only=True))
    return model.eval()


def estimator_probabilities(batch: BeliefBatch, make, read) -> np.ndarray:
    """[B, T, n] P(G[i, target] != 0) of an estimate fed each episode's observations."""
    params = NeuronParams()
    episodes, steps, n = batch.voltages.shape
    targets = np.flatnonzero(batch.is_target.reshape(-1)) % n  # [B]
    out = np.zeros((episodes, steps, n))
    for b in range(episodes):
        tracker, estimate = ObservedState(n, params, 0.0), make(n)
        for t in range(steps):
            estimate.add(*tracker.observe(batch.voltages[b, t], int(batch.actions[b, t])))
            out[b, t] = read(estimate)[:, targets[b]]
        out[b, :, targets[b]] = 0.0
    return out


def gaussian(estimate: ConnectivityEstimate) -> np.ndarray:
    excites, inhibits = estimate.entry_probabilities()
    return excites + inhibits


def marginal(estimate) -> np.ndarray:
    """P(G != 0) of a posterior over {-1, 0, +1} from its mean and sd: E[G^2]."""
    mean, sd = estimate.posterior()
    return np.clip(sd**2 + mean**2, 0.0, 1.0)


def step_times(model: AmortisedBelief, n: int, repeats: int = 300) -> tuple[float, float]:
    """(p50, p99) ms of one :meth:`AmortisedBelief.step` on one episode of n neurons."""
    features = torch.zeros(1, n, model.encode[0].in_features)
    state, times = None, []
    with torch.no_grad():
        for _ in range(repeats):
            started = time.perf_counter()
            _, state = model.step(features, state)
            times.append((time.perf_counter() - started) * 1e3)
    return float(np.percentile(times, 50)), float(np.percentile(times, 99))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, default=Path("docs/results/amortised-belief"))
    parser.add_argument("--sizes", type=int, nargs="+", default=[8, 16, 32, 64])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--particles", action="store_true")
    arguments = parser.parse_args()
    torch.set_num_threads(1)
    model = load(arguments.run)
    rows = []
    for index, (name, behaviour) in enumerate(BEHAVIOURS.items()):
        for n in arguments.sizes:
            rng = np.random.default_rng([HELD_OUT_SEED, n, index])
            batch = belief_batch(rng, n, arguments.episodes, 60, behaviour)
            beliefs = {"amortised": synapse_probabilities(model, batch)}
            beliefs["gaussian"] = estimator_probabilities(
                batch, lambda n: ConnectivityEstimate(n, NOISE_FREE_RESIDUAL_SD), gaussian
            )
            if n <= 11:
                beliefs["exact"] = estimator_probabilities(
                    batch, lambda n: DiscreteConnectivityEstimate(n, NOISE_FREE_RESIDUAL_SD),
                    marginal,
                )  # fmt: skip
            if arguments.particles:
                beliefs["particles"] = estimator_probabilities(
                    batch, lambda n: ParticleConnectivityEstimate(n, NOISE_FREE_RESIDUAL_SD),
                    marginal,
                )  # fmt: skip
            for estimator, probability in beliefs.items():
                every = belief_scores(probability, batch, tuple(range(1, 61)))
                mean = {
                    "after_steps": "mean",
                    "cross_entropy": float(np.mean([r["cross_entropy"] for r in every])),
                    "base_rate_cross_entropy": every[0]["base_rate_cross_entropy"],
                }
                mean["removed"] = 1.0 - mean["cross_entropy"] / mean["base_rate_cross_entropy"]
                for row in [every[k - 1] for k in AFTER_STEPS] + [mean]:
                    rows.append({"behaviour": name, "n": n, "estimator": estimator,
                                 "episodes": arguments.episodes, **row})  # fmt: skip
    with open(arguments.run / "scores.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({key: round(value, 4) if isinstance(value, float) else value
                             for key, value in row.items()})  # fmt: skip
    print(
        "| behaviour | n | estimator | "
        + " | ".join(f"after {k}" for k in AFTER_STEPS)
        + " | mean of 1..60 |"
    )
    print("|---|---:|---|" + "---:|" * (len(AFTER_STEPS) + 1))
    keys = sorted({(r["behaviour"], r["n"], r["estimator"]) for r in rows},
                  key=lambda key: (list(BEHAVIOURS).index(key[0]), key[1], key[2]))  # fmt: skip
    for key in keys:
        cells = [
            f"{r['cross_entropy']:.3f} ({100 * r['removed']:.0f} %)"
            for r in rows
            if (r["behaviour"], r["n"], r["estimator"]) == key
        ]
        print(f"| {key[0]} | {key[1]} | {key[2]} | " + " | ".join(cells) + " |")
    bases = sorted({(r["behaviour"], r["n"], r["base_rate_cross_entropy"]) for r in rows})
    for behaviour, n, base in bases:
        print(f"base rate, {behaviour}, n = {n}: {base:.3f} nats")
    for n in arguments.sizes:
        p50, p99 = step_times(model, n)
        print(
            f"belief step (network only, one thread), n = {n}: p50 {p50:.3f} ms, p99 {p99:.3f} ms"
        )


if __name__ == "__main__":
    main()
