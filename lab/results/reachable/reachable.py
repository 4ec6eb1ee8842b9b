"""What better identification could buy on each n = 8 task of the suite (validation
sets, never the test sets): the named identify-and-plan, the same loop told the
target's column of G (its inputs) from step k on (k = 1: every step but the first
action; k = 5), and told every weight. Normalised against do nothing and the oracle
planner on the same validation networks.

    python lab/results/reachable/reachable.py docs/results/reachable

Writes ``reachable-per-network.csv`` and prints the table of ``reachable.md``.
"""

from __future__ import annotations

import copy
import csv
import sys
from pathlib import Path

import numpy as np

from spikectl.experiments import suite
from spikectl.planning.identify import ConnectivityEstimate
from spikectl.planning.policy import IdentifyAndPlan, environment_settings
from spikectl.planning.release import settled_releases

TASKS = ("paper", "noise1", "noise2", "noise4", "hidden25", "stochastic", "background")
"""The suite's n = 8 tasks but ``heterogeneous``, whose planner plans known synapses at
their estimated strengths and its own neurons: told signs would plan it worse than it
plays (told its neurons and strengths: docs/results/heterogeneous-neurons)."""
TOLD_FROM = (1, 5)


def observed_weights(context) -> np.ndarray:
    """[k, k] the signed weights among the observed neurons (agent indexing)."""
    if context.hidden is None or len(context.hidden) == 0:
        return np.asarray(context.weights)
    seen = np.setdiff1d(np.arange(context.weights.shape[0]), context.hidden)
    return np.asarray(context.weights)[np.ix_(seen, seen)]


class ToldColumn:
    """Stands in for an estimate: the estimate's answers, but the target's column is the
    truth (known, sd 0) once the policy has reached step ``told_from``."""

    def __init__(self, estimate, truth: np.ndarray, target: int, told_from: int) -> None:
        self._inner, self._truth, self._target = estimate, truth.astype(np.int8), target
        self._told_from, self.step = told_from, 0
        self.n_neurons = estimate.n_neurons

    @property
    def version(self) -> int:  # a new version once told, so cached planning weights go
        return self._inner.version + (1 << 40 if self._told() else 0)

    def _told(self) -> bool:
        return self.step >= self._told_from

    def add(self, *evidence) -> None:
        self._inner.add(*evidence)

    def weights(self, known_sd: float):
        signs, known = self._inner.weights(known_sd)
        if self._told():
            signs, known = signs.copy(), known.copy()
            signs[:, self._target], known[:, self._target] = self._truth[:, self._target], True
        return signs, known

    def posterior(self):
        mean, sd = self._inner.posterior()
        if self._told():
            mean, sd = mean.copy(), sd.copy()
            mean[:, self._target], sd[:, self._target] = self._truth[:, self._target], 0.0
        return mean, sd

    def entry_probabilities(self):
        excites, inhibits = self._inner.entry_probabilities()
        if self._told():
            excites, inhibits = excites.copy(), inhibits.copy()
            excites[:, self._target] = self._truth[:, self._target] > 0
            inhibits[:, self._target] = self._truth[:, self._target] < 0
        return excites, inhibits

    def excitation_probability(self, target: int, known_sd: float) -> np.ndarray:
        if self._told() and target == self._target:
            return (self._truth[:, target] > 0).astype(np.float64)
        return self._inner.excitation_probability(target, known_sd)

    def relay_signs(self, known_sd: float) -> np.ndarray:
        """The relays through hidden neurons (``hidden25``), learned as before: the told
        column is the target's direct inputs."""
        return self._inner.relay_signs(known_sd)

    def sample(self, known_sd, connection_uniforms, sign_uniforms) -> np.ndarray:
        drawn = self._inner.sample(known_sd, connection_uniforms, sign_uniforms)
        if self._told():
            drawn = drawn.copy()
            drawn[:, :, self._target] = self._truth[None, :, self._target]
        return drawn


class Told(IdentifyAndPlan):
    """The named controller told the target's column from step ``told_from`` on (None:
    told every weight from the start), read from the set by the environment's context
    index (a diagnostic: the policy never sees it otherwise)."""

    def __init__(self, contexts, told_from: int | None, **settings) -> None:
        super().__init__(**settings)
        self.contexts, self.told_from = contexts, told_from

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def _release_evidence(self, residual, observed) -> tuple:
        # The policy settles stochastic releases only for its own Gaussian estimate (a
        # type check the wrapper does not pass): settle them here as the named
        # controller does, with the told column's synapse probabilities.
        wrapped = isinstance(self.estimate, ToldColumn)
        if (wrapped and self._settles_releases and self._chances.any()
                and isinstance(self.estimate._inner, ConnectivityEstimate)):  # fmt: skip
            excites, inhibits = self.estimate.entry_probabilities()
            return settled_releases(self._chances, residual, observed, excites, inhibits)
        return super()._release_evidence(residual, observed)

    def act(self, observation, info) -> int:
        step = int(observation["step"])
        truth = observed_weights(self.contexts[int(info["context_index"])])
        if step == 0 and self.told_from is None:
            self.known_weights = truth
        if step > 0 and self.told_from is not None:
            self.estimate.step = step
        action = super().act(observation, info)
        if step == 0 and self.told_from is not None:
            target = int(observation["target"])
            self.estimate = ToldColumn(self.estimate, truth, target, self.told_from)
        return action


def settings(task: str) -> dict:
    extensions = suite.task(task).extensions
    return {"noise_mV": extensions.observation_noise_mV,
            **environment_settings(extensions, suite.task(task).n_neurons)}  # fmt: skip


def main(out: Path) -> None:
    variants = {"identify-and-plan": "named", **{f"told the target's inputs from step {k}": k
                for k in TOLD_FROM}, "told every weight": None}  # fmt: skip
    rows, table = [], []
    for task in TASKS:
        contexts = suite.load_split(task, "validation")
        nothing, oracle = suite.references(task, "validation")
        cells = []
        for label, told_from in variants.items():
            if told_from == "named":
                controller = IdentifyAndPlan(**settings(task))
            else:
                controller = Told(contexts, told_from, **settings(task))
            returns, _ = suite.play(task, "validation", controller)
            rows += [{"task": task, "controller": label, "context": index, "return": float(value)}
                     for index, value in enumerate(returns)]  # fmt: skip
            normalised = (returns.mean() - nothing) / (oracle - nothing)
            cells.append((returns.mean(), normalised))
        table.append((task, cells))
    with open(out / "reachable-per-network.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print("| task | " + " | ".join(variants) + " |")
    print("|---|" + "---:|" * len(variants))
    for task, cells in table:
        values = " | ".join(f"{raw:.3f} ({norm:.3f})" for raw, norm in cells)
        print(f"| `{task}` | {values} |")
    means = np.array([[norm for _, norm in cells] for _, cells in table]).mean(axis=0)
    print("| **mean normalised** | " + " | ".join(f"**{value:.3f}**" for value in means) + " |")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
