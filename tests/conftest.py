"""Fixtures shared by several test modules (no test module imports another)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import torch


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own, which reads these options
def pytest_cmdline_main(config: pytest.Config) -> None:
    """The whole suite (`pytest`, `pytest -m slow`: no file named) runs on every core, up
    to 4, when pytest-xdist is installed (the dev extra): one test file per worker, so a
    module's fixtures are built once. A named file or test, `-n N` or `-p no:xdist` runs
    as asked; so does a run without pytest-xdist, in one process."""
    if (
        config.pluginmanager.hasplugin("xdist")
        and not hasattr(config, "workerinput")  # a worker: the suite is already shared out
        and config.option.numprocesses is None
        and config.args_source == pytest.Config.ArgsSource.TESTPATHS
    ):
        config.option.numprocesses = "auto"
        config.option.maxprocesses = config.option.maxprocesses or 4
        if config.option.dist == "no":
            config.option.dist = "loadfile"
        # One PyTorch/BLAS thread per worker (the workers inherit it): workers of two
        # threads each on as many cores spin against each other and take longer.
        os.environ.setdefault("OMP_NUM_THREADS", "1")


def _comparable(rows: list[dict]) -> list[dict]:
    from spikectl.training.run_files import CLOCK_FIELDS

    return [
        {k: None if v != v else v for k, v in row.items() if k not in CLOCK_FIELDS} for row in rows
    ]


def _assert_same_weights(path_a: Path, path_b: Path) -> None:
    a = torch.load(path_a, weights_only=True)
    b = torch.load(path_b, weights_only=True)
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key


@pytest.fixture
def comparable() -> Callable[[list[dict]], list[dict]]:
    """Metrics rows without the clocks, which no two runs share (NaN made comparable)."""
    return _comparable


@pytest.fixture
def assert_same_weights() -> Callable[[Path, Path], None]:
    """Assert that two saved state dicts (model.pt) hold bit-identical tensors."""
    return _assert_same_weights


def _assert_same_trials(dir_a: Path, dir_b: Path) -> None:
    from spikectl.experiments.sweep import trial_dirs
    from spikectl.training.run_files import read_metrics

    names = sorted(path.name for path in trial_dirs(dir_a))
    assert names == sorted(path.name for path in trial_dirs(dir_b)) and names
    for name in names:
        a, b = dir_a / "trials" / name, dir_b / "trials" / name
        assert _comparable(read_metrics(a)) == _comparable(read_metrics(b))
        _assert_same_weights(a / "model.pt", b / "model.pt")


@pytest.fixture
def assert_same_trials() -> Callable[[Path, Path], None]:
    """Assert that two sweep directories hold the same trials with the same metrics (but
    the clocks) and bit-identical final weights."""
    return _assert_same_trials


def _run_cli(*args: str, check: bool = True, env: dict | None = None):
    return subprocess.run(
        [sys.executable, "-m", "spikectl.cli", *args], capture_output=True, text=True,
        check=check, env=env,
    )  # fmt: skip


def _wait_until(
    condition: Callable[[], bool],
    what: str,
    timeout_s: float,
    process: subprocess.Popen | None = None,
) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert process is None or process.poll() is None, f"the process ended before {what}"
        assert time.monotonic() < deadline, f"no {what} within {timeout_s} s"
        time.sleep(0.02)


@pytest.fixture
def run_cli() -> Callable[..., subprocess.CompletedProcess]:
    """Run ``python -m spikectl.cli *args`` in a subprocess, capturing its output
    (``check``: raise on a non-zero exit; ``env``: the subprocess's environment)."""
    return _run_cli


@pytest.fixture
def wait_until() -> Callable[..., None]:
    """Poll ``condition()`` every 20 ms until it holds: fail after ``timeout_s``, or as soon
    as ``process`` (when given) has exited, naming ``what`` was awaited."""
    return _wait_until


@pytest.fixture
def easy_network_config(tmp_path):
    """A smoke-sized DRQN config on one easy 3-neuron network (stimulating neuron 0 fires
    the target one step later), tested on another: training must clearly beat doing
    nothing on it. The context files are saved under ``tmp_path``."""
    import numpy as np

    from spikectl import ContextSet, make_context
    from spikectl.training.presets import SMOKE

    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 2] = 1
    witness = np.full(12, -1)
    witness[[2, 8]] = 0
    easy = make_context(weights, target=2, pattern=np.eye(12)[3] + np.eye(12)[9], witness=witness)
    other = make_context(np.array([[0, 1, 0], [0, 0, 1], [0, 1, 0]]), target=2, seed=0,
                         episode_length=12)  # fmt: skip
    ContextSet([easy]).save(tmp_path / "train.npz")
    ContextSet([other]).save(tmp_path / "test.npz")
    return SMOKE.with_changes(
        arch="drqn", n_neurons=3, episode_length=12, total_env_steps=12 * 8 * 50,
        train_contexts=tmp_path / "train.npz", test_contexts=tmp_path / "test.npz",
        updates_per_round=16, learning_rate=3e-3, eval_every_episodes=160,
        checkpoint_every_episodes=400, epsilon_anneal_fraction=0.3, gamma=0.9,
    )  # fmt: skip


@pytest.fixture(scope="module")
def splits():
    """Small train/test context sets (20 + 20 networks, context seed 0) for the planners."""
    from spikectl.contexts import make_splits

    return make_splits(20, 20, seed=0)


def spike_pattern(length: int, spikes: list[int]):
    """A boolean target pattern of ``length`` steps, True at ``spikes``."""
    import numpy as np

    pattern = np.zeros(length, dtype=bool)
    pattern[spikes] = True
    return pattern


def play_legally(env, policy, seeds) -> None:
    """Play an episode of ``policy`` on ``env`` reset with each of ``seeds``, asserting
    that every action is legal (the paper's environment also raises on one that is not)."""
    for seed in seeds:
        observation, info = env.reset(seed=seed)
        policy.reset()
        terminated = False
        while not terminated:
            action = policy.act(observation, info)
            assert info["action_mask"][action + 1]
            observation, _, terminated, _, info = env.step(action)


def play_by_hand(policy, weights, target, pattern, first_actions, observed=None, steps=None):
    """Play ``policy`` on the paper's deterministic simulator of the full network
    ``weights`` [n, n] (int8), showing it only the neurons ``observed`` (agent indexing;
    None: all, the others hidden), with ``first_actions`` forced, for ``steps`` steps
    (None: the pattern's length). Returns (the actions played, the target's spike at
    each step), both lists."""
    import numpy as np

    from spikectl.neuron.params import NeuronParams
    from spikectl.neuron.simulator import SimulatorState, advance

    params = NeuronParams()
    n = weights.shape[0]
    observed = np.arange(n) if observed is None else np.asarray(observed)
    state = SimulatorState.at_rest(1, n, params)
    mask = np.ones(len(observed) + 1, dtype=bool)
    mask[target + 1] = False
    voltage, spikes = np.full((1, 1, n), params.v_rest_mV), np.zeros((1, 1, n), dtype=bool)
    last, actions, fired = -1, [], []
    for step in range(pattern.shape[0] if steps is None else steps):
        observation = {"voltage": voltage[0, 0, observed].copy(), "step": step,
                       "last_action": last, "pattern": pattern, "target": target}  # fmt: skip
        action = policy.act(observation, {"action_mask": mask})
        last = first_actions[step] if step < len(first_actions) else action
        actions.append(last)
        simulated = -1 if last == -1 else int(observed[last])
        advance(state, weights[None], np.array([[simulated]]), params, voltage, spikes)
        fired.append(bool(spikes[0, 0, observed[target]]))
    return actions, fired


@pytest.fixture
def interrupt_after_rounds(monkeypatch) -> Callable[[int], Callable[[], None]]:
    """``stop = interrupt_after_rounds(n)``: the training loop raises KeyboardInterrupt
    after its n-th round from now on (as Ctrl-C would); ``stop()`` undoes it."""
    from spikectl.training import run as run_module

    real_round = run_module.Loop.round

    def interrupt(rounds: int) -> Callable[[], None]:
        calls = {"n": 0}

        def round_then_die(self):
            real_round(self)
            calls["n"] += 1
            if calls["n"] == rounds:
                raise KeyboardInterrupt

        monkeypatch.setattr(run_module.Loop, "round", round_then_die)
        return lambda: monkeypatch.setattr(run_module.Loop, "round", real_round)

    return interrupt


@contextmanager
def no_hang(seconds: int = 60) -> Iterator[None]:
    """Fail with TimeoutError (instead of hanging the test run) if the block blocks."""

    def expired(signum, frame):
        raise TimeoutError(f"blocked for {seconds} s")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def run_main(argv: list[str], capsys) -> tuple[int, str, str]:
    """Run the ``spikectl`` command in this process: (exit code, stdout, stderr)."""
    from spikectl import cli

    try:
        cli.main(argv)
        code = 0
    except SystemExit as exit_:
        code = exit_.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def step_alike(batched, sync, actions):
    """Step a ``NeuronControlVectorEnv`` and a ``SyncVectorEnv`` of single environments
    with the same ``actions``, asserting equal rewards, terminations and ``info``'s
    spikes where the single environments report them; (obs_a, info_a, obs_b)."""
    import numpy as np

    obs_a, rewards_a, terminated_a, _, info_a = batched.step(actions)
    obs_b, rewards_b, terminated_b, _, info_b = sync.step(actions)
    np.testing.assert_array_equal(rewards_a, rewards_b)
    np.testing.assert_array_equal(terminated_a, terminated_b)
    present = info_b.get("_spikes", np.zeros(len(actions), dtype=bool))
    np.testing.assert_array_equal(info_a["_spikes"], present)
    if present.any():
        np.testing.assert_array_equal(info_a["spikes"][present], info_b["spikes"][present])
    return obs_a, info_a, obs_b


def assert_flat_vector_env_steps_as_singles(vector_class, single_class, kwargs, steps,
                                            num_envs=3):  # fmt: skip
    """A flat vector environment and ``num_envs`` single ones built from the same
    ``kwargs`` observe, reward and terminate alike for ``steps`` random actions (illegal
    ones do nothing, in both), through the vector env's next-step autoresets."""
    import numpy as np

    batched = vector_class(num_envs, **kwargs)
    singles = [single_class(**kwargs) for _ in range(num_envs)]
    assert batched.single_observation_space == singles[0].observation_space
    obs_a, _ = batched.reset(seed=4)
    obs_b = [env.reset(seed=4 + i)[0] for i, env in enumerate(singles)]
    rng = np.random.default_rng(1)
    ended = [False] * num_envs
    for _ in range(steps):
        np.testing.assert_array_equal(obs_a, np.stack(obs_b))
        actions = rng.integers(0, 9, num_envs)
        obs_a, rewards, terminated, *_ = batched.step(actions)
        stepped = []
        for i, (env, action) in enumerate(zip(singles, actions, strict=True)):
            # The vector env's next-step autoreset: the step after the last resets.
            stepped.append((env.reset()[0], 0.0, False) if ended[i] else env.step(int(action)))
            ended[i] = stepped[-1][2]
        obs_b = [s[0] for s in stepped]
        np.testing.assert_array_equal(rewards, [s[1] for s in stepped])
        np.testing.assert_array_equal(terminated, [s[2] for s in stepped])
