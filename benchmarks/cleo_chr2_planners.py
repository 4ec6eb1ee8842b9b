"""The ChR2-aware planners in Cleo: the oracle and identify-and-plan made for
``Extensions(actuator="chr2")`` (they plan the light with the opsin's state), played on
the paper task's first --networks unseen test networks in spikectl's ChR2 environment
and in the Cleo bridge's ``chr2`` setting (docs/cleo.md). Prints each controller's mean
return in both, the largest difference of one episode's returns, and in how many
episodes the two chose the same actions. Runs in the Cleo virtualenv (minutes):

    PYTHONPATH=$PWD /tmp/venv-cleo/bin/python benchmarks/cleo_chr2_planners.py --networks 30
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from spikectl.bridges.cleo import SETTINGS, CleoLoop
from spikectl.envs.controller import play_episode
from spikectl.envs.env import NeuronControlEnv
from spikectl.experiments.suite import load_split
from spikectl.neuron.extensions import Extensions
from spikectl.training.loaders import load_controller


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--networks", type=int, default=30)
    parser.add_argument("--planners", nargs="+", default=["oracle", "identify-and-plan"])
    arguments = parser.parse_args()
    contexts = load_split("paper", "test")
    env = NeuronControlEnv(contexts=contexts, extensions=Extensions(actuator="chr2"))
    loop = CleoLoop(contexts, SETTINGS["chr2"])
    print("| controller | spikectl chr2 | Cleo chr2 | largest difference | same actions |")
    print("|---|---:|---:|---:|---:|")
    for name in arguments.planners:
        controller = load_controller(name, env=env)
        ours, theirs, same = [], [], 0
        started = time.process_time()
        for context in range(arguments.networks):
            actions, total = play_episode(env, controller, context)
            episode = loop.play(controller, context)
            ours.append(total)
            theirs.append(episode.total)
            same += int(np.array_equal(episode.actions, actions))
        ours, theirs = np.array(ours), np.array(theirs)
        print(f"| {name} | {ours.mean():.4f} | {theirs.mean():.4f} | "
              f"{np.abs(ours - theirs).max():.2e} | {same}/{arguments.networks} |  "
              f"({time.process_time() - started:.0f} CPU s)", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
