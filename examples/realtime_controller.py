"""A controller on the 1 kHz real-time rig.

``run_realtime`` paces any controller (``reset()`` and ``act(observation, info)``)
against the environment at a wall-clock rate, times every decision against its
deadline and, when a decision is late, lets the stimulator do nothing in that frame.
The controller here is identify-and-plan (no training); pass a run directory to play a
trained agent, with ``--compiled`` for its Numba policy without PyTorch:

    python examples/realtime_controller.py [--controller identify-and-plan] [--episodes 5]
    python examples/realtime_controller.py --controller runs/tdrqn-guided-seed0 --compiled

The command line does the same: ``spikectl realtime identify-and-plan --episodes 5``.
The rig spins on the clock between frames: it keeps one core busy while it runs.
"""

from __future__ import annotations

import argparse

import spikectl
from spikectl.envs.realtime import run_realtime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controller", default="identify-and-plan")
    parser.add_argument("--compiled", action="store_true")
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--rate-hz", type=float, default=1000.0)
    parser.add_argument("--short", action="store_true", help="one episode at 100 Hz (tests)")
    args = parser.parse_args()
    episodes, rate = (1, 100.0) if args.short else (args.episodes, args.rate_hz)

    train, test = spikectl.make_splits(n_train=10, n_test=10, seed=0)
    env = spikectl.NeuronControlEnv(contexts=test)
    if args.compiled:
        controller = spikectl.load_controller(args.controller, compiled=True)
    else:
        controller = spikectl.load_controller(args.controller, env=env)
    report = run_realtime(env, controller, contexts=range(episodes), rate_hz=rate)
    summary = report.summary()
    print(
        f"{args.controller} at {rate:.0f} Hz, {episodes} episode(s): "
        + ", ".join(f"{key} {value:.4g}" for key, value in summary.items())
    )


if __name__ == "__main__":
    main()
