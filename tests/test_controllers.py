"""One controller interface (issue 24, part 1): every controller plays one environment
with reset()/act() and a vector environment with act_batch, and both agree; load_controller
builds each by name or from a file; evaluate and the rig play them."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import spikectl
from spikectl import ContextSet, NeuronControlEnv, NeuronControlVectorEnv, make_splits
from spikectl.agents.policy_file import PolicyFileError
from spikectl.envs.controller import (
    BatchController,
    Controller,
    Copies,
    DoNothing,
    RandomLegal,
    batched,
    play_episode,
)
from spikectl.envs.rollout import evaluate_policy, run_episodes
from spikectl.planning import OraclePlanner, plan_episode
from spikectl.training.evaluate import evaluate_run
from spikectl.training.loaders import CONTROLLERS, load_controller
from spikectl.training.run_files import read_config
from spikectl.training.run_sets import baseline_episodes

ROOT = Path(__file__).resolve().parent.parent
RUN = ROOT / "tests" / "data" / "format2-smoke-run"


@pytest.fixture(scope="module")
def contexts():
    return make_splits(4, 4, 5, 20, seed=3)[1]


def single_play(controller: Controller, contexts) -> tuple[np.ndarray, np.ndarray]:
    """(actions [S, N], returns [S]): one episode per context on a single environment."""
    env = NeuronControlEnv(contexts=contexts)
    played = [play_episode(env, controller, i, seed=0) for i in range(len(contexts))]
    return np.stack([actions for actions, _ in played]), np.array([ret for _, ret in played])


def assert_same_play(controller: Controller, batch, contexts) -> None:
    actions, returns = single_play(controller, contexts)
    np.testing.assert_array_equal(actions, batch.actions)
    np.testing.assert_allclose(returns, batch.returns, rtol=0, atol=1e-12)  # summing order


@pytest.mark.parametrize("name", ["do-nothing", "identify-and-plan", "oracle", "witness"])
def test_every_named_controller_plays_alone_and_batched_alike(name, contexts):
    env = NeuronControlVectorEnv(num_envs=len(contexts), contexts=contexts)
    controller = load_controller(name, env=env)
    assert isinstance(controller, Controller)
    assert isinstance(batched(controller), BatchController)
    env.reset(seed=0)
    batch = run_episodes(env, np.arange(len(contexts)), controller)
    assert_same_play(controller, batch, contexts)
    expected = {"do-nothing": 0.5, "witness": 1.0}
    if name in expected:
        np.testing.assert_allclose(batch.returns, expected[name])


def test_the_oracle_controller_scores_what_plan_episode_finds(contexts):
    oracle = OraclePlanner(contexts, width=16)
    _, returns = single_play(oracle, contexts)
    planned = [plan_episode(context, width=16)[1] for context in contexts]
    np.testing.assert_allclose(returns, planned)
    # Plans are kept per (context, latency): here latency 0, read from the observation.
    assert set(oracle.plans) == {(c, 0) for c in range(len(contexts))}
    assert oracle.plan_seconds > 0


def test_a_trained_network_plays_alone_as_in_the_batch(contexts):
    # per_environment: the guarantee holds by construction, whatever the CPU's kernels do
    # with the batch size (a single batched forward does not promise it: greedy.py).
    run_contexts = spikectl.ContextSet.load(RUN / "test_contexts.npz")
    controller = load_controller(RUN, model="best", per_environment=True)
    assert_same_play(controller, evaluate_policy(run_contexts, controller), run_contexts)


def test_per_environment_play_does_not_depend_on_the_batch():
    """A context's actions are the same alone and in batches of several sizes beside other
    contexts (other rows changed), and the same as act() gives; the Q-values too."""
    train = spikectl.ContextSet.load(RUN / "train_contexts.npz")
    test = spikectl.ContextSet.load(RUN / "test_contexts.npz")
    controller = load_controller(RUN, model="best", per_environment=True)
    alone = evaluate_policy(test[:1], controller).actions[0]  # [N]
    assert np.array_equal(alone, single_play(controller, test[:1])[0][0])
    batches = [
        spikectl.ContextSet([test[0], *train[: size - 1]], test.params, test.seed, test.extensions)
        for size in (2, 3, 7)
    ] + [spikectl.ContextSet([*train[2:5], test[0]], test.params, test.seed, test.extensions)]
    for batch in batches:
        row = next(i for i, context in enumerate(batch) if context is test[0])
        np.testing.assert_array_equal(evaluate_policy(batch, controller).actions[row], alone)


def test_evaluate_compiled_plays_the_runs_compiled_policy(monkeypatch):
    """``evaluate_run(compiled=True)`` plays the run's compiled policy, exactly as that
    policy plays when given to evaluate_policy. That it picks the network's actions is
    test_compiled_policy.py's (up to near-ties: it runs on NumPy's kernels, the network
    on PyTorch's, which order a near-tie differently on some CPUs, so the two are not
    compared bit for bit here)."""
    from spikectl.agents.compiled import CompiledPolicy
    from spikectl.training import evaluate as evaluate_module

    loaded = []

    def spy(*args, **kwargs):
        loaded.append(load_controller(*args, **kwargs))
        return loaded[-1]

    monkeypatch.setattr(evaluate_module, "load_controller", spy)
    results = evaluate_run(RUN, model="best", compiled=True)
    assert [type(controller) for controller in loaded] == [CompiledPolicy]
    files = {"train": "train_contexts.npz", "test": "test_contexts.npz",
             "validation": "val_contexts.npz"}  # fmt: skip
    assert [result.name for result in results] == list(files)
    config = read_config(RUN)
    for result in results:
        contexts = ContextSet.load(RUN / files[result.name])
        direct = load_controller(RUN, model="best", compiled=True)
        episodes = baseline_episodes(config, contexts, direct)
        np.testing.assert_array_equal(result.returns, episodes.returns)


def test_random_legal_is_seeded_and_legal(contexts):
    first = evaluate_policy(contexts, RandomLegal(7))
    second = evaluate_policy(contexts, RandomLegal(7))
    np.testing.assert_array_equal(first.actions, second.actions)
    assert not np.array_equal(first.actions, evaluate_policy(contexts, RandomLegal(8)).actions)
    legal = first.action_mask[np.arange(len(contexts))[:, None], first.actions + 1]
    assert legal.all()


def test_copies_give_each_environment_its_own_state(contexts):
    class Counter:
        def __init__(self):
            self.steps = 0

        def reset(self):
            self.steps = 0

        def act(self, observation, info):
            assert int(observation["step"]) == self.steps  # its own episode, in order
            self.steps += 1
            return -1

    copies = batched(Counter())
    assert isinstance(copies, Copies)
    episodes = evaluate_policy(contexts, copies)
    assert [c.steps for c in copies.copies] == [contexts.episode_length] * len(contexts)
    np.testing.assert_allclose(episodes.returns, 0.5)


def test_load_controller_refuses_what_it_cannot_build(tmp_path, contexts):
    with pytest.raises(FileNotFoundError, match="not one of do-nothing"):
        load_controller("identify-and-pla")
    with pytest.raises(ValueError, match="oracle controller .* give env= or contexts="):
        load_controller("oracle")
    with pytest.raises(ValueError, match="model must be one of"):
        load_controller(RUN, model="last")
    with pytest.raises(TypeError, match="env must be a spikectl NeuronControlEnv"):
        load_controller("identify-and-plan", env=object())
    with pytest.raises(TypeError, match="is not a controller"):
        batched(lambda observations, infos: None)
    (tmp_path / "policy.npz").write_bytes(b"not a zip")
    with pytest.raises(PolicyFileError, match="not a readable"):
        load_controller(tmp_path / "policy.npz")
    assert load_controller("witness", contexts=contexts).witnesses.shape == (4, 20)
    # The library's, first (a test may register more: tests/test_registries.py).
    assert CONTROLLERS.names()[:5] == ("do-nothing", "random", "identify-and-plan", "oracle",
                                       "witness")  # fmt: skip
    assert isinstance(load_controller("do-nothing"), DoNothing)


def test_named_controllers_play_their_contexts_params(contexts):
    """The planners' neuron model is the contexts' (or the env's); params= beside them
    must be theirs, and serves alone where no contexts are given."""
    other = spikectl.NeuronParams(release_scale=0.8)
    assert load_controller("oracle", contexts=contexts).params == contexts.params
    assert load_controller("identify-and-plan", contexts=contexts, params=contexts.params)
    assert load_controller("identify-and-plan", params=other).params == other
    env = NeuronControlEnv(contexts=contexts)
    for given in ({"contexts": contexts}, {"env": env}):
        with pytest.raises(ValueError, match="release_scale 0.8 .*leave params out"):
            load_controller("oracle", params=other, **given)


def test_identify_and_plan_takes_its_seed(contexts):
    """``seed`` reaches the networks QMDP draws (the ``spikes`` composition has QMDP):
    the same controller as built by hand with that seed, other draws than seed 0's."""
    from spikectl.planning import IdentifyAndPlan

    extensions = spikectl.Extensions(sensing="spikes")
    env = NeuronControlEnv(contexts=contexts, extensions=extensions)
    draws = {}
    for seed in (0, 3):
        controller = load_controller("identify-and-plan", env=env, seed=seed)
        by_hand = IdentifyAndPlan(contexts.params, controller.composition,
                                  extensions=extensions, seed=seed)  # fmt: skip
        assert controller.seed == seed and controller.composition.decision.gamble is not None
        played, expected = (play_episode(env, c, 0, seed=0) for c in (controller, by_hand))
        np.testing.assert_array_equal(played[0], expected[0])
        np.testing.assert_array_equal(controller.uniforms[0], by_hand.uniforms[0])
        draws[seed] = controller.uniforms[0]
    assert not np.array_equal(draws[0], draws[3])


def test_a_compiled_policy_file_loads_without_pytorch(tmp_path):
    from spikectl.agents import export_policy
    from spikectl.training.loaders import load_agent

    export_policy(load_agent(RUN, model="best"), tmp_path / "policy.npz")
    script = (
        "import sys, spikectl\n"
        f"controller = spikectl.load_controller({str(tmp_path / 'policy.npz')!r})\n"
        "print(type(controller).__name__, 'torch' in sys.modules)\n"
    )
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["CompiledPolicy", "False"]


def test_the_realtime_command_writes_every_decision(run_cli, tmp_path):
    out = tmp_path / "decisions.csv"
    result = run_cli("realtime", "do-nothing", "--episodes", "2", "--out", str(out))
    assert "deadline misses:" in result.stdout and "mean return 0.500" in result.stdout
    lines = out.read_text().splitlines()
    assert lines[0] == "episode,step,latency_ms,missed" and len(lines) == 1 + 2 * 60
    assert lines[-1].startswith("1,59,")
    result = run_cli("realtime", str(RUN), "--compiled", "--model", "best", "--episodes", "3")
    assert "CompiledPolicy paced at 1000 Hz" in result.stdout
    assert "3 episodes on the generated test set (5 neurons, seed 0)" in result.stdout


@pytest.mark.parametrize(
    "args, message",
    [
        (["realtime", "do-nothing", "--episodes", "0"], "--episodes must be an integer >= 1"),
        (["realtime", "do-nothing", "--episodes", "101"], "has 100 contexts"),
        (["realtime", "do-nothing", "--cpu", "4096"], "--cpu 4096: this process may run on"),
        (["realtime", "do-nothing", "--rate-hz", "0"], "--rate-hz must be a number in"),
        (["realtime", "no-such-controller"], "not one of do-nothing"),
        (["realtime", "random", "--env", "CartPole-v1"], "is not a spikectl environment"),
    ],
)
def test_the_realtime_command_refuses_bad_input(run_cli, args, message):
    result = run_cli(*args, check=False)
    assert result.returncode == 2
    assert message in result.stderr and "Traceback" not in result.stderr
