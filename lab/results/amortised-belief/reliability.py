"""The amortised belief's calibration (issue 61, item 1): reliability curves, and its
cross-entropy on episodes identify-and-plan played (a behaviour it was not trained on).

    python lab/results/amortised-belief/reliability.py --belief BELIEF.pt \
        --planner-episodes N8.npz N16.npz --out docs/results/amortised-belief

``reliability.csv``: on measure.py's held-out ``mix`` episodes (the same networks and
actions), every P(G[i, target] != 0) of steps 1..60 (the target excluded) binned by
tenths, each bin's count, mean predicted probability and observed frequency, for the
trained belief, identify-and-plan's Gaussian estimate fed the same observations and,
at n <= 11, the exact posterior; and the expected calibration error (the count-weighted
mean of |predicted - observed|). ``reliability.png`` draws the curves.

``planner.csv``: the episodes ``lab/results/belief-policy/collect.py`` wrote with
identify-and-plan acting (its training networks regenerated from the file's context
indices), read step by step through the controller's own feature tracker: the belief's
and the Gaussian estimate's binary cross-entropy after 10, 25 and 50 steps and over every
step, against the base rate.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
from pathlib import Path

import numpy as np
import torch

from spikectl import NeuronParams
from spikectl.agents.amortised_belief import FEATURES
from spikectl.agents.amortised_controller import load_belief
from spikectl.agents.amortised_kernel import BeliefFeatureTracker, target_prior
from spikectl.planning import ConnectivityEstimate, DiscreteConnectivityEstimate
from spikectl.training.belief import belief_scores, synapse_probabilities
from spikectl.training.belief_episodes import BehaviourMix, BeliefBatch, belief_batch

HERE = Path(__file__).resolve().parent


def script(name: str, path: Path):
    """A research script of the lab, imported as a module."""
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


measure = script("measure", HERE / "measure.py")
collect = script("collect", HERE.parent / "belief-policy" / "collect.py")

BINS = np.linspace(0.0, 1.0, 11)


def reliability_rows(probability: np.ndarray, batch: BeliefBatch) -> list[dict]:
    """One row per bin of every step's P(synapse) (the target excluded)."""
    truth = np.broadcast_to((batch.labels > 0)[:, None, :], probability.shape)
    keep = np.broadcast_to(~batch.is_target[:, None, :], probability.shape)
    predicted, observed = probability[keep], truth[keep]
    which = np.clip(np.digitize(predicted, BINS) - 1, 0, len(BINS) - 2)
    rows = []
    for k in range(len(BINS) - 1):
        chosen = which == k
        if chosen.any():
            rows.append({"bin_low": BINS[k], "bin_high": BINS[k + 1], "count": int(chosen.sum()),
                         "predicted": float(predicted[chosen].mean()),
                         "observed": float(observed[chosen].mean())})  # fmt: skip
    return rows


def planner_batch(path: Path, params: NeuronParams) -> BeliefBatch:
    """The collected episodes as a batch of T - 1 steps: step t's features are those of
    the observation after action t (the last observation after the last action is not
    recorded)."""
    data = dict(np.load(path))
    n, contexts = int(data["n"]), data["context"]
    networks = collect.training_networks(n, int(contexts.max()) + 1)
    episodes, steps = data["taken"].shape
    features = np.empty((episodes, steps - 1, n, len(FEATURES)), dtype=np.float32)
    weights = np.stack([networks[int(c)].weights for c in contexts]).astype(np.int8)
    for e in range(episodes):
        tracker = BeliefFeatureTracker(n, int(data["target"][e]), params)
        for t in range(1, steps):
            features[e, t - 1] = tracker.row(data["voltage"][e, t], int(data["last_action"][e, t]))
    targets = data["target"].astype(np.int64)
    column = weights[np.arange(episodes), :, targets]  # [B, n]: G[i, target]
    labels = np.where(column > 0, 1, np.where(column < 0, 2, 0)).astype(np.int64)
    is_target = np.arange(n)[None, :] == targets[:, None]
    prior = np.stack([target_prior(n, int(t)) for t in targets])
    return BeliefBatch(features, labels, is_target, prior, weights,
                       data["taken"][:, :-1].astype(np.int64), data["voltage"][:, 1:])  # fmt: skip


def write(path: Path, rows: list[dict]) -> None:
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows({key: round(value, 5) if isinstance(value, float) else value
                          for key, value in row.items()} for row in rows)  # fmt: skip
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--belief", type=Path, required=True)
    parser.add_argument("--planner-episodes", type=Path, nargs="*", default=[])
    parser.add_argument("--sizes", type=int, nargs="+", default=[8, 16, 32, 64])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--out", type=Path, default=Path("docs/results/amortised-belief"))
    arguments = parser.parse_args()
    torch.set_num_threads(1)
    model, params = load_belief(arguments.belief), NeuronParams()
    gaussian = (lambda n: ConnectivityEstimate(n, measure.NOISE_FREE_RESIDUAL_SD), measure.gaussian)
    exact = (lambda n: DiscreteConnectivityEstimate(n, measure.NOISE_FREE_RESIDUAL_SD),
             measure.marginal)  # fmt: skip
    rows, curves = [], {}
    for n in arguments.sizes:
        rng = np.random.default_rng([measure.HELD_OUT_SEED, n, 0])  # measure.py's "mix"
        batch = belief_batch(rng, n, arguments.episodes, 60, BehaviourMix())
        beliefs = {"amortised": synapse_probabilities(model, batch),
                   "gaussian": measure.estimator_probabilities(batch, *gaussian)}  # fmt: skip
        if n <= 11:
            beliefs["exact"] = measure.estimator_probabilities(batch, *exact)
        for estimator, probability in beliefs.items():
            bins = reliability_rows(probability, batch)
            total = sum(row["count"] for row in bins)
            error = sum(row["count"] * abs(row["predicted"] - row["observed"]) for row in bins)
            curves[(n, estimator)] = bins
            for row in bins:
                rows.append({"n": n, "estimator": estimator, **row,
                             "calibration_error": error / total})  # fmt: skip
            print(f"n = {n}, {estimator}: expected calibration error {error / total:.4f}")
    write(arguments.out / "reliability.csv", rows)
    planner_rows = []
    for path in arguments.planner_episodes:
        batch = planner_batch(path, params)
        n = batch.features.shape[2]
        beliefs = {"amortised": synapse_probabilities(model, batch),
                   "gaussian": measure.estimator_probabilities(batch, *gaussian)}  # fmt: skip
        for estimator, probability in beliefs.items():
            every = belief_scores(probability, batch, tuple(range(1, probability.shape[1] + 1)))
            for k in (10, 25, 50):
                planner_rows.append({"n": n, "episodes": batch.features.shape[0],
                                     "estimator": estimator, **every[k - 1]})  # fmt: skip
            mean = float(np.mean([row["cross_entropy"] for row in every]))
            base = every[0]["base_rate_cross_entropy"]
            planner_rows.append({"n": n, "episodes": batch.features.shape[0],
                                 "estimator": estimator, "after_steps": "mean",
                                 "cross_entropy": mean, "base_rate_cross_entropy": base,
                                 "removed": 1.0 - mean / base})  # fmt: skip
            print(planner_rows[-4:])
    if planner_rows:
        write(arguments.out / "planner.csv", planner_rows)
    figure(curves, arguments.out / "reliability.png")


def figure(curves: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = sorted({n for n, _ in curves})
    fig, axes = plt.subplots(1, len(sizes), figsize=(3.2 * len(sizes), 3.2), sharey=True)
    for axis, n in zip(np.atleast_1d(axes), sizes, strict=True):
        axis.plot([0, 1], [0, 1], color="0.7", linewidth=1)
        for (size, estimator), bins in curves.items():
            if size == n:
                axis.plot([b["predicted"] for b in bins], [b["observed"] for b in bins],
                          marker="o", markersize=3, label=estimator)  # fmt: skip
        axis.set_title(f"n = {n}")
        axis.set_xlabel("predicted P(synapse onto the target)")
    np.atleast_1d(axes)[0].set_ylabel("observed frequency")
    np.atleast_1d(axes)[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
