"""A spikectl controller driving a Brian 2 network in Cleo's closed loop (docs/cleo.md).

Plays identify-and-plan (or CONTROLLER: a run directory, a compiled policy file, or a
named controller) on the first networks of the benchmark's unseen test set, once in
spikectl's environment and once in Cleo per setting, and prints the returns side by side:

    python examples/cleo_closed_loop.py [--controller identify-and-plan] [--networks 3]
        [--settings ideal chr2 latency2]

Needs the cleo extra: pip install -c constraints-cleo.txt -e ".[cleo]"
"""

from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controller", default="identify-and-plan")
    parser.add_argument("--networks", type=int, default=3, help="test networks to play")
    parser.add_argument("--settings", nargs="+", default=["ideal", "chr2", "latency2"])
    args = parser.parse_args(argv)

    from spikectl.config_errors import MissingExtraError

    try:
        from spikectl.bridges.cleo import SETTINGS, CleoLoop
    except MissingExtraError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    from spikectl.envs.controller import play_episode
    from spikectl.envs.env import NeuronControlEnv
    from spikectl.experiments.suite import load_split
    from spikectl.training.loaders import load_controller

    unknown = [name for name in args.settings if name not in SETTINGS]
    if unknown or not 1 <= args.networks <= 100:
        print(f"error: settings must be among {', '.join(SETTINGS)} and --networks in 1..100",
              file=sys.stderr)  # fmt: skip
        return 2
    contexts = load_split("paper", "test")
    env = NeuronControlEnv(contexts=contexts)
    controller = load_controller(args.controller, env=env)
    print(f"{args.controller} on test networks 0..{args.networks - 1}")
    print("network  spikectl  " + "  ".join(f"{name:>9}" for name in args.settings))
    loops = {name: CleoLoop(contexts, SETTINGS[name]) for name in args.settings}
    for context in range(args.networks):
        _, total = play_episode(env, controller, context)
        row = [loops[name].play(controller, context) for name in args.settings]
        print(f"{context:7d}  {total:8.3f}  " + "  ".join(f"{e.total:9.3f}" for e in row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
