"""What a stimulation teaches about the target's column: for each stimulation of a ready
neuron whose synapse onto the target is unknown, whether that synapse is known once the
release's effect has been observed (two steps later), and if not, why: the neuron did
not release, the target was refractory when the release arrived, or other neurons whose
synapses onto the target are unknown released with it (confounded). The named
controller on the first N validation networks of a task (a diagnosis; it changes
nothing).

    python docs/results/confounded-zeros/diagnose_probes.py TASK N
"""

from __future__ import annotations

import copy
import sys
from collections import Counter

from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.planning.policy import IdentifyAndPlan, environment_settings


class Diagnosed(IdentifyAndPlan):
    """The named controller, counting what each stimulation taught (``counts``)."""

    counts: Counter = Counter()

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def act(self, observation, info) -> int:
        step = int(observation["step"])
        if step == 0:
            self._pending: dict[int, dict] = {}
        before = self.probes + self.gambles
        action = super().act(observation, info)
        probe = self.probes + self.gambles > before
        target = int(observation["target"])
        known = self._planning_weights()[1]
        if step + 1 in self._pending:  # the step the stimulated neuron spiked and released
            record = self._pending[step + 1]
            record["released"] = self._tracker.state.released[0].copy()
            record["target spiked"] = bool(self._tracker.spiked[target])
        if step in self._pending:  # the release's effect on the target has been observed
            record = self._pending.pop(step)
            stimulated = record["neuron"]
            others = record["released"] & ~record["known"]
            others[stimulated] = False
            if known[stimulated, target]:
                outcome = "known"
            elif not record["released"][stimulated]:
                outcome = "did not release"
            elif record["target spiked"]:
                outcome = "target refractory"
            else:
                outcome = "confounded" if others.any() else "other"
            phase = "steps 0-9" if record["step"] < 10 else "steps 10-59"
            self.counts[(phase, "probe" if probe or record["probe"] else "plan", outcome)] += 1
        if action >= 0 and not known[action, target] and self._ready()[action]:
            self._pending[step + 2] = {"neuron": action, "step": step, "probe": probe,
                                       "known": known[:, target].copy()}  # fmt: skip
        return action


def main(task: str, size: int) -> None:
    spec = suite.task(task)
    contexts = suite.load_split(task, "validation")[:size]
    controller = Diagnosed(**environment_settings(spec.extensions, spec.n_neurons))
    returns = evaluate_policy(
        contexts, controller, extensions=spec.extensions, seed=suite.suite_version(1).env_seed
    ).returns
    print(f"{task}, first {size} validation networks: mean return {returns.mean():.4f}")
    print("| steps | chosen by | synapse onto the target two steps later | stimulations |")
    print("|---|---|---|---:|")
    for (phase, chooser, outcome), count in sorted(Diagnosed.counts.items()):
        print(f"| {phase} | {chooser} | {outcome} | {count} |")


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
