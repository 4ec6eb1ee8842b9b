"""Where would a one-step improvement over identify-and-plan gain? At each step of its
own episodes, every legal action is played once, each followed by the teacher's own
continuation to the end on the true network (deep copies of the environment and of the
teacher, which reads the deviation in its next observation and replans). The best
action's return minus the teacher's is what an AggreVaTe-style learner could gain at that
state if it knew the network: an upper bound, since a learner sees only the history.

    python lab/results/advisor/deviation.py TASK SPLIT FIRST COUNT STEPS

plays networks FIRST .. FIRST+COUNT-1 of the task's SPLIT (never ``test``), steps
0 .. STEPS-1, and prints the share of states where some action beats the teacher's and
the mean gain, by step. A research script: the library is unchanged.
"""

from __future__ import annotations

import copy
import sys
import time

import numpy as np

from spikectl.envs import NeuronControlEnv
from spikectl.experiments import suite
from spikectl.planning import IdentifyAndPlan, named_composition

BANDS = ((0, 1), (1, 5), (5, 10), (10, 20), (20, 30), (30, 60))


def continuation_return(env, teacher, action: int) -> float:
    """The return from now: ``action``, then the teacher to the end (on copies)."""
    env, teacher = copy.deepcopy(env), copy.deepcopy(teacher)
    observation, reward, terminated, truncated, info = env.step(action)
    total = reward
    while not (terminated or truncated):
        observation, reward, terminated, truncated, info = env.step(teacher.act(observation, info))
        total += reward
    return float(total)


def main() -> None:
    task, split = sys.argv[1], sys.argv[2]
    first, count, steps = (int(value) for value in sys.argv[3:6])
    if split == "test":
        raise SystemExit("choose on train or validation; the test set is played once")
    contexts = suite.load_split(task, split)
    spec = suite.task(task)
    composition = named_composition(spec.extensions, spec.n_neurons)
    rows = []  # (network, step, best return - the teacher's)
    started = time.process_time()
    for k in range(first, first + count):
        env = NeuronControlEnv(contexts=contexts[k : k + 1], extensions=spec.extensions)
        observation, info = env.reset(seed=suite.suite_version(1).env_seed)
        teacher = IdentifyAndPlan(composition=composition, extensions=spec.extensions)
        for step in range(steps):
            # The teacher reads this observation and decides first; the copies then see
            # each deviation in the next observation's last action.
            action = teacher.act(observation, info)
            values = {
                int(a): continuation_return(env, teacher, int(a))
                for a in np.flatnonzero(info["action_mask"]) - 1
            }
            rows.append((k, step, max(values.values()) - values[action]))
            observation, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
    table = np.array(rows)
    gain = table[:, 2]
    print(f"{task} {split}, networks {first}-{first + count - 1}, steps 0-{steps - 1}: "
          f"{len(table)} states, {time.process_time() - started:.0f} CPU s")  # fmt: skip
    print(f"  all steps: share {(gain > 1e-9).mean():.3f}, mean gain {gain.mean():.4f}")
    for low, high in BANDS:
        chosen = (table[:, 1] >= low) & (table[:, 1] < high)
        if chosen.any():
            print(f"  steps {low}-{high - 1}: share {(gain[chosen] > 1e-9).mean():.3f}, "
                  f"mean gain {gain[chosen].mean():.4f}")  # fmt: skip


if __name__ == "__main__":
    main()
