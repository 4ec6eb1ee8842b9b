"""The edits of the column controller's rule that did not help (docs/results/column-belief,
"What did not help"): each played on suite v1's ``n16`` and ``n32`` validation sets and
printed beside the rule as committed.

    python lab/results/column-belief/variants.py      # about 2 CPU-minutes

``probes K W``: probe on quiet stretches until K inputs are likely (P >= ``probe_below``)
rather than 1, when the next W steps want no spike (5 in the committed rule).
``probe_below``: the committed rule at another ``probe_below``. ``two-hop τ β``: with
identify-and-plan's whole estimate of G (``ConnectivityEstimate``), on the step before a
wanted one, stimulate the neuron i with the highest P(i -> j) P(j -> target) over the
neurons j that one input makes spike then, when it exceeds τ and no direct input more
likely than β can land at the next step; else the committed rule on the same estimate.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.column import DECIMALS, GaussianColumn
from spikectl.agents import amortised_controller
from spikectl.agents.amortised_controller import PROBE_FLOOR, AmortisedController
from spikectl.agents.amortised_kernel import BeliefFeatureTracker
from spikectl.experiments import suite
from spikectl.neuron import DO_NOTHING
from spikectl.planning import ConnectivityEstimate, IdentifyAndPlan, ObservedState

TASKS = ("n16", "n32")


def probing(known_inputs: int, quiet_steps: int):
    """``choose_action`` probing until ``known_inputs`` inputs are likely, when the next
    ``quiet_steps`` steps want no spike."""

    def choose(excitatory, can_land, ahead, rule="greedy", rng=None, probe_below=0.5):
        score = np.where(can_land, excitatory, -1.0)
        best = int(np.argmax(score))
        if ahead.size == 0 or not ahead[0]:
            known = int((excitatory >= probe_below).sum())
            probe = (not ahead[:quiet_steps].any() and known < known_inputs
                     and score[best] >= PROBE_FLOOR)  # fmt: skip
            return best if probe else DO_NOTHING
        return best if score[best] > 0.0 else DO_NOTHING

    return choose


class TwoHop(AmortisedController):
    """The committed rule on identify-and-plan's whole estimate of G, with a second hop
    (module docstring); ``tau`` None: never the second hop."""

    def __init__(self, params, tau: float | None, beta: float) -> None:
        super().__init__(GaussianColumn(), params)  # its belief unused: act reads the estimate
        self.tau, self.beta = tau, beta

    def spawn(self, index: int) -> TwoHop:
        return TwoHop(self.params, self.tau, self.beta)

    def act(self, observation, info) -> int:
        step, p = int(observation["step"]), self.params
        voltage = np.asarray(observation["voltage"], dtype=np.float64)
        pattern = np.asarray(observation["pattern"]).astype(bool)
        legal = np.asarray(info["action_mask"], dtype=bool)[1:]
        n, target = voltage.shape[0], int(observation["target"])
        if step == 0:
            self.tracker = BeliefFeatureTracker(n, target, p)
            self.estimate = ConnectivityEstimate(n, IdentifyAndPlan().observation.residual_sd)
            self.observed = ObservedState(n, p, 0.0)
        else:
            action = int(observation.get("last_action", DO_NOTHING))
            self.tracker.row(voltage, action)
            self.estimate.add(*self.observed.observe(voltage, action))
        excites = np.round(self.estimate.entry_probabilities()[0], DECIMALS)  # [pre, post]
        direct = excites[:, target].copy()  # [n]
        direct[target] = 0.0
        can_land = self.can_land(legal)
        ahead = pattern[step + 1 : step + 1 + p.min_release_interval_steps]
        if self.tau is not None and ahead.size > 1 and not ahead[0] and ahead[1]:
            tracker = self.tracker
            rested_then = tracker.since + 2 >= p.min_release_interval_steps
            free_then = tracker.refractory_left <= 1
            now = tracker.after_reset - (tracker.after_reset - p.v_rest_mV) * p.leak_per_step
            then = now - (now - p.v_rest_mV) * p.leak_per_step + p.synaptic_step_mV
            relays = np.where(rested_then & free_then & (then >= p.v_spike_mV), direct, 0.0)
            relays[target] = 0.0
            path = excites * relays[None, :]  # [i, j]: P(i -> j) P(j -> target)
            np.fill_diagonal(path, 0.0)
            # A direct input stimulated now would make the target spike (and rest) too soon.
            value = np.where(can_land & (direct < 0.2), path.max(axis=1) * (1.0 - direct), -1.0)
            next_direct = legal & rested_then & free_then
            best_next = direct[next_direct].max() if next_direct.any() else 0.0
            chosen = int(np.argmax(value))
            if value[chosen] > self.tau and best_next < self.beta:
                return chosen
        return amortised_controller.choose_action(direct, can_land, ahead, "greedy", None,
                                                  self.probe_below)  # fmt: skip


def on_both(make) -> list[float]:
    """The validation mean return on each of TASKS of ``make(params)``'s controller."""
    return [float(np.mean(suite.play(task, "validation",
                                     make(suite.load_split(task, "validation", 1).params),
                                     version=1)[0]))
            for task in TASKS]  # fmt: skip


def main() -> None:
    committed = amortised_controller.choose_action
    base = on_both(lambda params: AmortisedController(GaussianColumn(), params))
    print("| edit | `n16` | `n32` |\n|---|---:|---:|")
    print(f"| the committed rule | {base[0]:.4f} | {base[1]:.4f} |")
    for known, quiet in ((2, 5), (3, 5), (1, 3), (1, 1)):
        amortised_controller.choose_action = probing(known, quiet)
        try:
            scores = on_both(lambda params: AmortisedController(GaussianColumn(), params))
        finally:
            amortised_controller.choose_action = committed
        print(f"| probes {known} {quiet} | " + " | ".join(
            f"{s - b:+.3f}" for s, b in zip(scores, base, strict=True)) + " |")  # fmt: skip
    for below in (0.8, 0.95, 1.0):
        scores = on_both(lambda params, below=below: AmortisedController(
            GaussianColumn(), params, probe_below=below))  # fmt: skip
        print(f"| probe_below {below} | " + " | ".join(
            f"{s - b:+.3f}" for s, b in zip(scores, base, strict=True)) + " |")  # fmt: skip
    whole = on_both(lambda params: TwoHop(params, None, 1.0))
    print(f"| the committed rule on the whole estimate | {whole[0]:.4f} | {whole[1]:.4f} |")
    for tau, beta in ((0.1, 1.01), (0.3, 1.01), (0.3, 0.9), (0.5, 0.9), (0.3, 0.5), (0.6, 1.01)):
        scores = on_both(lambda params, tau=tau, beta=beta: TwoHop(params, tau, beta))
        print(f"| two-hop {tau} {beta} | " + " | ".join(
            f"{s - b:+.3f}" for s, b in zip(scores, whole, strict=True)) + " |")  # fmt: skip


if __name__ == "__main__":
    main()
