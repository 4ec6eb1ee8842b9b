"""How often a network that reads the planner's advice does what the advice says:
played on the first COUNT validation networks of a suite task, its action against the
advised one at every step (the advice is read from the controller's own inputs).

    python lab/results/advice-input/agreement.py --task n16 --run RUN [--count 25]
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.suite import load_split, task
from spikectl.neuron.simulator import DO_NOTHING
from spikectl.training.controllers import load_agent
from spikectl.training.greedy import greedy_controller


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="paper")
    parser.add_argument("--run", required=True)
    parser.add_argument("--count", type=int, default=25)
    args = parser.parse_args()
    torch.set_num_threads(1)
    chosen = task(args.task)
    contexts = load_split(args.task, "validation")[: args.count]
    controller = greedy_controller(
        load_agent(args.run, n_neurons=chosen.n_observed), None, chosen.extensions
    )
    advised: list[np.ndarray] = []
    with_inputs = controller._with_belief

    def recording(observations, mask):
        inputs = with_inputs(observations, mask)
        advice = inputs["belief"][..., -2:]  # [S, n, 2]: advised, waits
        advised.append(np.where(advice[:, 0, 1] == 1, DO_NOTHING, advice[..., 0].argmax(-1)))
        return inputs

    controller._with_belief = recording
    episodes = evaluate_policy(contexts, controller, extensions=chosen.extensions, seed=0)
    advice = np.stack(advised, axis=1)  # [S, N]
    acts, waits = episodes.actions >= 0, episodes.actions == DO_NOTHING
    print(
        f"{args.task} ({args.count} validation networks): return {episodes.returns.mean():.3f}, "
        f"follows the advice on {(advice == episodes.actions).mean():.3f} of the steps; "
        f"stimulates where the advice waits {(acts & (advice == DO_NOTHING)).mean():.3f}, "
        f"waits where it is advised to stimulate {(waits & (advice >= 0)).mean():.3f}"
    )


if __name__ == "__main__":
    main()
