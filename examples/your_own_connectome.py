"""Your own connectome: build contexts from connectivity matrices with ``make_context``,
check them with the simulator, and play them in the environment.

A connectivity matrix is n x n with entries in {-1, 0, 1} (inhibitory, none,
excitatory; row = presynaptic neuron). What you do not give (the target, the pattern
and the witness action sequence that proves it reachable) is generated from ``seed``.

    python examples/your_own_connectome.py [--short]
"""

from __future__ import annotations

import argparse

import numpy as np

import spikectl


def ring(n: int) -> np.ndarray:
    """Each neuron excites the next; every third one also inhibits the one after."""
    weights = np.zeros((n, n), dtype=np.int8)
    for i in range(n):
        weights[i, (i + 1) % n] = 1
        if i % 3 == 0:
            weights[i, (i + 2) % n] = -1
    return weights


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--short", action="store_true", help="two contexts (the tests)")
    args = parser.parse_args()
    n_contexts = 2 if args.short else 8

    contexts = [spikectl.make_context(ring(8), seed=seed) for seed in range(n_contexts)]
    context_set = spikectl.ContextSet(contexts)
    for index, context in enumerate(contexts):
        # The witness reproduces the pattern exactly: the best return is 1.
        voltages, spikes = spikectl.simulate(context.weights, context.witness)
        assert (spikes[:, context.target] == context.pattern).all()
        print(
            f"context {index}: target n{context.target}, "
            f"{int(context.pattern.sum())} wanted spikes, "
            f"{int((context.witness >= 0).sum())} stimulations in the witness"
        )

    env = spikectl.NeuronControlEnv(contexts=context_set)
    witness = spikectl.load_controller("witness", env=env)
    returns = []
    for index in range(len(context_set)):
        witness.reset()
        observation, info = env.reset(seed=index, options={"context": index})
        total, done = 0.0, False
        while not done:
            observation, reward, terminated, truncated, info = env.step(
                witness.act(observation, info)
            )
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    print(f"the witness scores {np.round(returns, 3).tolist()} on your networks")
    if not args.short:
        path = context_set.save("my_contexts.npz")
        print(f"saved {path}; train on it: spikectl train --train-contexts {path}")


if __name__ == "__main__":
    main()
