"""Why the student does not follow its teacher at 32 neurons: measured on validation.

    python lab/results/student-n32-diagnosis/diagnose.py --task n32 \
        --run RUN_DIR[:N_NEURONS] [--run ...] [--model final|best]

Plays identify-and-plan (the guided learner's teacher, its constructor's settings) beside
each student on the task's 100 validation networks (never the test set): the student
acts, the planner reads the same observations (which include the student's actions)
and says what it would do. Each step the planner acts is classed by what the planner
does there: a *probe* (it stimulates a neuron whose synapses it has not identified, to
learn them) or a *planned* stimulation (its plan on what it knows). Per class: how often
the student chooses the same action, does nothing, or stimulates a true excitatory input
of the target (the context's hidden weights: an action the planner's model would count
as near-equivalent once known). And, over every stimulation, how often each controller
stimulates a true excitatory input of the target. ``RUN_DIR:32`` plays a run trained at
another size on the task's size (per-neuron networks).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

from spikectl import IdentifyAndPlan
from spikectl.agents import GreedyController
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.suite import load_split
from spikectl.training.loaders import load_agent

# The student beside its teacher, as the diagnosis at 8 neurons plays them.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from diagnose_student import DO_NOTHING, BesidePlanner  # noqa: E402


def excitatory_inputs(contexts) -> np.ndarray:
    """[S, n] whether neuron j excites the target of network s (its hidden weights)."""
    return np.stack([context.weights[:, context.target] > 0 for context in contexts])


def second_hop_inputs(contexts) -> np.ndarray:
    """[S, n] whether neuron j, not itself an excitatory input of the target, excites one."""
    rows = []
    for context in contexts:
        direct = context.weights[:, context.target] > 0
        rows.append(~direct & ((context.weights[:, direct] > 0).any(axis=1)))
    return np.stack(rows)


def share(mask: np.ndarray, of: np.ndarray) -> str:
    return f"{mask[of].mean():.2f}" if of.any() else "  - "


def report(
    name: str, beside: BesidePlanner, returns: np.ndarray, inputs: np.ndarray, second: np.ndarray
) -> None:
    chosen, planned, probe = (
        np.concatenate([record[i] for record in beside.steps]) for i in (1, 2, 3)
    )  # each [steps x networks], step-major
    steps = np.concatenate([np.full(len(record[1]), record[0]) for record in beside.steps])
    network = np.concatenate([np.arange(len(record[1])) for record in beside.steps])

    def hits(actions: np.ndarray, of: np.ndarray) -> np.ndarray:
        return (actions != DO_NOTHING) & of[network, np.maximum(actions, 0)]

    acts, student_acts = planned != DO_NOTHING, chosen != DO_NOTHING
    same = chosen == planned
    print(f"{name}: return {returns.mean():.3f}; agreement with the planner "
          f"{same.mean():.2f} over all steps")  # fmt: skip
    classes = (
        ("planner probes", acts & probe),
        ("planner plans", acts & ~probe),
        ("planner does nothing", ~acts),
    )
    for label, where in classes:
        print(
            f"  {label:<22} {where.mean():.2f} of steps: student same {share(same, where)}, "
            f"does nothing {share(~student_acts, where)}, stimulates a true input "
            f"{share(hits(chosen, inputs), where)} (planner {share(hits(planned, inputs), where)})"
        )
    for low, high in ((0, 5), (5, 20), (20, 60)):
        where = (steps >= low) & (steps < high)
        mine, theirs = where & student_acts, where & acts
        print(
            f"  steps {low:>2}-{high - 1:<2}: same {share(same, where)}, planner probes "
            f"{share(probe & acts, where)}, student stimulates {share(student_acts, where)} "
            f"(planner {share(acts, where)}); of their stimulations a true input: student "
            f"{share(hits(chosen, inputs), mine)}, planner {share(hits(planned, inputs), theirs)}; "
            f"through an input (second hop): student {share(hits(chosen, second), mine)}, "
            f"planner {share(hits(planned, second), theirs)}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="n32")
    parser.add_argument("--run", action="append", default=[], help="RUN_DIR[:N_NEURONS]")
    parser.add_argument("--model", default="final", choices=("final", "best"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    contexts = load_split(args.task, "validation")
    inputs, second = excitatory_inputs(contexts), second_hop_inputs(contexts)
    n = inputs.shape[1]
    print(
        f"{args.task} validation: {len(contexts)} networks of {n} neurons; the target has "
        f"{inputs.sum(1).mean():.1f} excitatory inputs on average"
    )
    planner = evaluate_policy(contexts, IdentifyAndPlan())
    print(f"identify-and-plan alone: return {planner.returns.mean():.3f}")
    for spec in args.run:
        run, _, size = spec.partition(":")
        network = load_agent(run, n_neurons=int(size) if size else None, model=args.model)
        student = GreedyController(network)
        beside = BesidePlanner(student)
        episodes = evaluate_policy(contexts, beside)
        report(spec, beside, episodes.returns, inputs, second)


if __name__ == "__main__":
    main()
