"""spikectl's ChR2 actuator against Cleo's chr2 setting, on the paper task's test networks.

For each of the first N test networks a controller plays one episode in Cleo
(``CleoSetting(actuation="chr2")``) and one in ``NeuronControlEnv(extensions=
{"actuator": "chr2"})``: ``random`` (a seeded random controller) replays Cleo's actions,
the planners play closed loop in both. Prints the share of neuron-steps whose spike
agrees (every neuron, every step), the largest difference of an observed potential,
how many action sequences are identical, and the mean returns. Needs the Cleo extra
(docs/cleo.md):

    python benchmarks/cleo_opsin_agreement.py --networks 30 --controllers random oracle
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from spikectl.bridges.cleo import CleoLoop, CleoSetting
from spikectl.envs.controller import RandomLegal
from spikectl.envs.env import NeuronControlEnv
from spikectl.experiments.suite import load_split
from spikectl.training.loaders import load_controller


class Watching:
    """Lets ``inner`` act and keeps the potentials and actions it was shown and chose."""

    def __init__(self, inner) -> None:
        self.inner, self.seen, self.actions = inner, [], []

    def reset(self) -> None:
        self.inner.reset()
        self.seen, self.actions = [], []

    def act(self, observation, info) -> int:
        self.seen.append(observation["voltage"].copy())
        self.actions.append(int(self.inner.act(observation, info)))
        return self.actions[-1]


class Replay:
    def __init__(self, actions) -> None:
        self.actions = list(actions)

    def reset(self) -> None:
        pass

    def act(self, observation, info) -> int:
        return self.actions[observation["step"]]


def spikectl_episode(env: NeuronControlEnv, controller: Watching, context: int):
    """(raster [N, n], return) of one episode in spikectl."""
    controller.reset()
    observation, info = env.reset(options={"context": context})
    raster = np.zeros((env.episode_length, env.n_neurons), dtype=bool)
    total = 0.0
    for step in range(env.episode_length):
        observation, reward, _, _, info = env.step(controller.act(observation, info))
        raster[step], total = info["spikes"], total + reward
    return raster, total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--networks", type=int, default=30)
    parser.add_argument("--controllers", nargs="+", default=["random", "oracle"])
    args = parser.parse_args()
    test = load_split("paper", "test")
    loop = CleoLoop(test, CleoSetting(actuation="chr2"))
    env = NeuronControlEnv(contexts=test, extensions={"actuator": "chr2"})
    for name in args.controllers:
        started = time.process_time()
        agreeing = total_cells = same_actions = 0
        largest = 0.0
        returns = []
        for context in range(args.networks):

            def make(context=context, name=name):
                if name == "random":
                    return RandomLegal(seed=context)
                return load_controller(name, env=env, seed=context)

            in_cleo = Watching(make())
            episode = loop.play(in_cleo, context)
            cleo_raster = np.zeros((test.episode_length, test.n_neurons), dtype=bool)
            steps = np.rint(np.asarray(loop._spikes.t / loop._step)).astype(np.int64)
            cleo_raster[steps, np.asarray(loop._spikes.i)] = True
            ours = Watching(Replay(episode.actions) if name == "random" else make())
            raster, total = spikectl_episode(env, ours, context)
            agreeing += int((raster == cleo_raster).sum())
            total_cells += raster.size
            same_actions += ours.actions == in_cleo.actions
            largest = max(largest, float(np.abs(np.array(ours.seen) - in_cleo.seen).max()))
            returns.append((total, episode.total))
        spikectl_mean, cleo_mean = np.mean(returns, axis=0)
        print(f"{name}: {args.networks} networks; spikes agree in {agreeing:,} of "
              f"{total_cells:,} neuron-steps ({agreeing / total_cells:.2%}); largest observed "
              f"potential difference {largest:.3g} mV; identical action sequences "
              f"{same_actions}/{args.networks}; mean return spikectl {spikectl_mean:.4f}, "
              f"Cleo {cleo_mean:.4f} ({time.process_time() - started:.0f} s CPU)")  # fmt: skip


if __name__ == "__main__":
    main()
