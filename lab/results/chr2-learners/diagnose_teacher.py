"""Why the guided learner does not learn on suite v2's ``chr2``: what its teachers do there,
and what reward an explorer meets, on the first NETWORKS networks of the VALIDATION set
(never the test set), beside the same networks through the paper's current pulse.

    python lab/results/chr2-learners/diagnose_teacher.py [NETWORKS]

Prints, for each of the guided learner's two realisable teachers, told-weights (the
paper's composition told each network's weights) and identify (the task's named
composition, fast form), both at beam 32, on ``chr2`` and on ``paper`` (each task's own
validation set; the two share their networks): its return, the share of its actions
that do nothing, how many steps before a wanted target spike it last acted (on any
neuron, on an excitatory input of the target), which neurons it acts on, the lengths of
its runs of consecutive actions on one neuron, the share acting by step; and the return
of the guided preset's explorer at epsilon = 1 (do nothing with probability 0.75, else
a uniform legal neuron).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.told import Told
from spikectl.contexts import ContextSet
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.planning import Composition, IdentifyAndPlan, named_composition

VERSION, SPLIT, WIDTH = 2, "validation", 32
EXPLORE_DO_NOTHING = 0.75


def subset(task: str, networks: int) -> ContextSet:
    full = suite.load_split(task, SPLIT, VERSION)
    return ContextSet([full[i] for i in range(networks)], full.params, full.seed,
                      full.extensions)  # fmt: skip


def explorer(seed: int):
    rng = np.random.default_rng(seed)

    def act(observations, action_mask):  # [S, n + 1], column 0 = do nothing
        size = action_mask.shape[0]
        actions = np.full(size, -1, dtype=np.int64)
        for s in range(size):
            if rng.random() >= EXPLORE_DO_NOTHING:
                legal = np.flatnonzero(action_mask[s, 1:])
                actions[s] = rng.choice(legal)
        return actions

    return act


def lead_times(episodes, contexts) -> tuple[np.ndarray, np.ndarray]:
    """For each wanted target spike the teacher got: steps since the last action (any
    neuron), and steps since the last action on a presynaptic excitatory neuron of the
    target (-1: none in the episode so far)."""
    since_any, since_pre = [], []
    for s, context in enumerate(contexts):
        target = context.target
        weights = np.asarray(context.weights)
        exciters = set(np.flatnonzero(weights[:, target] > 0).tolist())
        pattern = np.asarray(context.pattern)
        actions = episodes.actions[s]
        for t in np.flatnonzero(pattern & episodes.spikes[s, :, target]):
            before = [u for u in range(t + 1) if actions[u] >= 0]
            since_any.append(t - before[-1] if before else -1)
            pre = [u for u in before if int(actions[u]) in exciters]
            since_pre.append(t - pre[-1] if pre else -1)
    return np.array(since_any), np.array(since_pre)


def input_shares(actions: np.ndarray, contexts) -> tuple[float, float, float]:
    """Of the actions on a neuron: the share on an excitatory input of the target, the
    share on a neuron two excitatory synapses upstream of it and on no such path;
    and the share of legal neurons that are excitatory inputs."""
    direct, two_hop, chance = [], [], []
    for s, context in enumerate(contexts):
        weights = np.asarray(context.weights)
        excites = weights > 0
        target = context.target
        into = excites[:, target]
        upstream = (excites.astype(int) @ into.astype(int)) > 0
        lit = actions[s][actions[s] >= 0]
        direct += into[lit].tolist()
        two_hop += (upstream[lit] & ~into[lit]).tolist()
        chance.append(into.sum() / (len(into) - 1))
    return float(np.mean(direct)), float(np.mean(two_hop)), float(np.mean(chance))


def run_lengths(actions: np.ndarray) -> np.ndarray:
    """Lengths of runs of the same non-idle action on consecutive steps."""
    lengths = []
    for row in actions:
        run = 0
        for t, a in enumerate(row):
            if a >= 0 and t > 0 and row[t - 1] == a:
                run += 1
            else:
                if run:
                    lengths.append(run)
                run = 1 if a >= 0 else 0
        if run:
            lengths.append(run)
    return np.array(lengths)


def histogram(values: np.ndarray, top: int = 8) -> str:
    counts = [(values == k).sum() for k in range(-1, top)] + [(values >= top).sum()]
    labels = ["none"] + [str(k) for k in range(top)] + [f">={top}"]
    total = max(1, len(values))
    return ", ".join(f"{lab}: {c / total:.2f}" for lab, c in zip(labels, counts, strict=True) if c)


def describe(name, teacher, contexts, extensions, seed) -> None:
    """Print what the teacher does on the networks (the module docstring's list)."""
    started = time.process_time()
    episodes = evaluate_policy(contexts, teacher, extensions=extensions, seed=seed)
    cpu = time.process_time() - started
    actions = episodes.actions
    since_any, since_pre = lead_times(episodes, list(contexts))
    wanted = np.array([np.asarray(c.pattern).sum() for c in contexts])
    print(f"{name} teacher: return {episodes.returns.mean():.3f} ({cpu:.0f} CPU s), "
          f"do nothing {np.mean(actions < 0):.3f} of steps, wanted spikes per episode "
          f"{wanted.mean():.2f}, hit {len(since_any) / wanted.sum():.3f} of them")  # fmt: skip
    print(f"  steps from its last action to a wanted spike it got: {histogram(since_any)}")
    print(f"  ... from its last action on an excitatory input of the target: "
          f"{histogram(since_pre)}")  # fmt: skip
    direct, two_hop, chance = input_shares(actions, list(contexts))
    print(f"  its lit/stimulated neurons: {direct:.2f} excitatory inputs of the target "
          f"({chance:.2f} of the neurons are), {two_hop:.2f} two excitatory synapses "
          "upstream only")  # fmt: skip
    runs = run_lengths(actions)
    print(f"  runs of one neuron on consecutive steps: {histogram(runs)}")
    per_step = np.mean(actions >= 0, axis=0)
    print(
        "  share acting by step (0-9, 10-19, ..):",
        " ".join(f"{per_step[i : i + 10].mean():.2f}" for i in range(0, 60, 10)),
    )


def main(networks: int) -> None:
    for task in ("chr2", "paper"):
        contexts = subset(task, networks)
        extensions = suite.task(task, VERSION).extensions
        seed = suite.suite_version(VERSION).env_seed
        teachers = {
            "told-weights": Told(contexts, composition=Composition().with_width(WIDTH),
                                 extensions=extensions),
            "identify": IdentifyAndPlan(contexts.params, named_composition(
                extensions, contexts[0].n_neurons, fast=True).with_width(WIDTH),
                extensions=extensions),
        }  # fmt: skip
        print(f"\n## {task}: {networks} validation networks")
        for name, teacher in teachers.items():
            describe(name, teacher, contexts, extensions, seed)
        for k in range(3):
            returns = evaluate_policy(contexts, explorer(k), extensions=extensions,
                                      seed=seed).returns  # fmt: skip
            print(f"explorer seed {k}: return {returns.mean():.4f} "
                  f"(min {returns.min():.3f}, max {returns.max():.3f})")  # fmt: skip


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 40)
