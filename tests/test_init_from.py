"""Training from given weights (``agent.init_from``): a run starts from a model file or a
run's best network, per-neuron weights move to another number of neurons (a curriculum
over sizes), weights that do not fit are one ConfigError, and a resume does not read them
again."""

from __future__ import annotations

import pytest
import torch

from spikectl.config_errors import ConfigError
from spikectl.training.agent_network import build_network
from spikectl.training.presets import SMOKE
from spikectl.training.run import train
from spikectl.training.run_files import read_metrics
from spikectl.training.torch_files import load_model_weights

SHORT = SMOKE.with_changes(total_env_steps=16 * 20)  # two rounds of 8 episodes


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A short smoke run at n = 5: its directory (model.pt, best_model.pt)."""
    run = tmp_path_factory.mktemp("source") / "run"
    train(SHORT, run)
    return run


def starting_from(path, **changes):
    return SHORT.with_changes(**changes).with_changes({"agent.init_from": path})


def same_weights(network: torch.nn.Module, weights: dict[str, torch.Tensor]) -> bool:
    state = network.state_dict()
    return state.keys() == weights.keys() and all(
        torch.equal(state[name], weights[name]) for name in state
    )


def test_a_network_starts_from_the_model_file_or_the_runs_best_network(trained):
    fresh = build_network(SHORT.with_changes(seed=1))
    assert not same_weights(fresh, load_model_weights(trained / "model.pt"))
    given = build_network(starting_from(trained / "model.pt", seed=1))
    assert same_weights(given, load_model_weights(trained / "model.pt"))
    from_run = build_network(starting_from(trained, seed=1))
    assert same_weights(from_run, load_model_weights(trained / "best_model.pt"))


def test_per_neuron_weights_play_at_another_number_of_neurons(trained):
    """TDRQN's weights do not depend on n: trained at 5 neurons, they start a network of
    12 that plays (one Q-value per neuron and one for doing nothing)."""
    weights = load_model_weights(trained / "model.pt")
    network = build_network(starting_from(trained / "model.pt", n_neurons=12))
    assert same_weights(network, weights)
    generator = torch.Generator().manual_seed(0)
    observations = {
        "voltage": -70 + 10 * torch.rand(1, 3, 12, generator=generator),
        "target": torch.full((1, 3), 4),
        "pattern": torch.randint(0, 2, (1, 3, 20), generator=generator).float(),
        "step": torch.arange(3).unsqueeze(0),
        "last_action": torch.tensor([[-1, 2, 7]]),
    }
    q_values, _ = network(observations)  # [1, T, n + 1]
    assert q_values.shape == (1, 3, 13)
    assert torch.isfinite(q_values).all()


def test_weights_that_do_not_fit_are_one_config_error(trained, tmp_path):
    with pytest.raises(ConfigError, match=r"init_from names no weights: .*missing.pt does not"):
        build_network(starting_from(tmp_path / "missing.pt"))
    fixed_size = SHORT.with_changes(arch="drqn")
    with pytest.raises(ConfigError, match=r"init_from names weights that do not fit .*model.pt"):
        build_network(fixed_size.with_changes({"agent.init_from": trained / "model.pt"}))
    with pytest.raises(ConfigError, match="do not fit"):
        narrower = SHORT.with_changes({"agent.sizes.lstm_hidden": 8})
        build_network(narrower.with_changes({"agent.init_from": trained / "model.pt"}))


def test_the_cli_refuses_weights_that_do_not_fit_in_one_line(trained, tmp_path, run_cli):
    result = run_cli(
        "train", "smoke", "--arch", "drqn", "--init-from", str(trained / "model.pt"),
        "--run-dir", str(tmp_path / "run"), check=False,
    )  # fmt: skip
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    assert "do not fit" in result.stderr
    assert result.stderr.startswith("spikectl: error: --init-from names weights")  # the flag
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not (tmp_path / "run").exists()  # refused before the run directory is made


def test_the_config_records_the_weights_a_run_started_from(trained, tmp_path):
    config = starting_from(trained / "model.pt")
    assert config.to_dict()["agent"]["init_from"] == str(trained / "model.pt")
    assert type(config).from_dict(config.to_dict()) == config


def test_a_resume_takes_the_checkpoints_weights_and_does_not_read_the_source_again(
    trained, tmp_path, interrupt_after_rounds, comparable
):
    import shutil

    source = tmp_path / "source"
    shutil.copytree(trained, source)
    config = SMOKE.with_changes(
        {"agent.init_from": source / "model.pt"}, total_env_steps=24 * 20,
        eval_every_episodes=8, checkpoint_every_episodes=8,
    )  # fmt: skip
    reference = tmp_path / "reference"
    train(config, reference)
    interrupted = tmp_path / "interrupted"
    stop = interrupt_after_rounds(2)
    with pytest.raises(KeyboardInterrupt):
        train(config, interrupted)
    stop()
    shutil.rmtree(source)
    train(config, interrupted, resume=True)
    assert comparable(read_metrics(interrupted)) == comparable(read_metrics(reference))
    assert same_weights_files(interrupted / "model.pt", reference / "model.pt")


def same_weights_files(a, b) -> bool:
    first, second = load_model_weights(a), load_model_weights(b)
    return first.keys() == second.keys() and all(torch.equal(first[k], second[k]) for k in first)


def test_weights_of_another_run_name_the_setting_and_both_values(trained):
    """The source run's config says why its weights do not fit: another episode length is
    named as such, not blamed on the architecture or the number of neurons."""
    cases = {
        "episode length 20 (this run: 30)": {"episode_length": 30},
        "arch tdrqn (this run: ddrqn)": {"arch": "ddrqn"},
        "sizes.lstm_hidden 16 (this run: 8)": {"agent.sizes.lstm_hidden": 8},
    }
    for expected, change in cases.items():
        for source in (trained, trained / "model.pt"):
            with pytest.raises(ConfigError) as caught:
                build_network(SHORT.with_changes(change).with_changes({"agent.init_from": source}))
            assert f"holds a network of {expected}" in str(caught.value), caught.value
            assert "architecture" not in str(caught.value)


def test_weights_copied_out_of_their_run_name_the_episode_length(trained, tmp_path):
    import shutil

    shutil.copy(trained / "model.pt", tmp_path / "model.pt")  # no config.json beside it
    with pytest.raises(ConfigError, match=r"an episode length of 20 steps \(this run: 30\)"):
        build_network(starting_from(tmp_path / "model.pt", episode_length=30))


def test_every_other_kind_of_file_is_named_with_what_init_from_takes(trained, tmp_path):
    from spikectl.agents import export_policy, make_agent
    from spikectl.contexts import make_splits

    export_policy(make_agent("tdrqn", 5, 20), tmp_path / "pol.npz")
    make_splits(3, 3, 5, 20, seed=4)[1].save(tmp_path / "ctx.npz")
    (tmp_path / "notes.txt").write_text("hello")
    takes = "it takes a run directory (its best_model.pt), or a model.pt or best_model.pt"
    for name, kind in (
        ("pol.npz", "a compiled policy file"), ("ctx.npz", "a context set file"),
        ("checkpoint.pt", "a training checkpoint (checkpoint.pt)"),
    ):  # fmt: skip
        path = trained / name if name == "checkpoint.pt" else tmp_path / name
        with pytest.raises(ConfigError) as caught:
            build_network(starting_from(path))
        message = str(caught.value)
        assert f"names {kind}" in message and str(path) in message and takes in message
        assert "enforce fail" not in message and "before checksums" not in message
    with pytest.raises(ConfigError, match=r"notes.txt is not a readable spikectl model: .*takes"):
        build_network(starting_from(tmp_path / "notes.txt"))


def test_the_cli_names_another_episode_length_in_one_line(trained, tmp_path, run_cli):
    result = run_cli(
        "train", "smoke", "--episode-length", "30", "--init-from", str(trained),
        "--run-dir", str(tmp_path / "run"), check=False,
    )  # fmt: skip
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines() == [
        f"spikectl: error: --init-from names weights that do not fit this network: "
        f"{trained / 'best_model.pt'} holds a network of episode length 20 (this run: 30)"
    ]
    assert not (tmp_path / "run").exists()
