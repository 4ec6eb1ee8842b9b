"""The per-neuron input features as registered entries (``spikectl.agents.inputs``,
``AgentSizes.inputs``): a feature added the public way (one function, one registry
line) is computed, learned from and played with; the names are checked; config.json
files written with the older booleans read back as the features they switched on."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

from spikectl.agents import make_agent
from spikectl.agents.compiled import CompiledPolicy
from spikectl.agents.greedy import GreedyController
from spikectl.agents.inputs import INPUT_FEATURES, InputFeature, input_width, per_neuron_inputs
from spikectl.config_errors import ConfigError
from spikectl.envs.rollout import evaluate_policy
from spikectl.training.config import Experiment
from spikectl.training.loaders import load_agent
from spikectl.training.presets import PRESETS, SMOKE
from spikectl.training.run import train
from spikectl.training.run_files import read_metrics


def step_fraction(obs, voltage, dtype):
    """[..., n, 1]: how far the episode has run, t / N, the same for every neuron."""
    fraction = obs["step"].to(dtype) / obs["pattern"].shape[-1]  # [...]
    return fraction[..., None, None].expand(*voltage.shape, 1)


STEP_FRACTION = InputFeature(1, step_fraction, "t / N, the same for every neuron")
INPUT_FEATURES.register("step-fraction", STEP_FRACTION)  # the one line that adds a feature
INPUTS = ("target", "step-fraction")


def test_a_registered_feature_is_computed_after_the_others():
    obs = {"voltage": torch.tensor([[-70.0, -50.0, -60.0]]), "last_action": torch.tensor([0]),
           "target": torch.tensor([2]), "step": torch.tensor([5]),
           "pattern": torch.zeros(1, 20)}  # fmt: skip
    x = per_neuron_inputs(obs, INPUTS, v_rest_mV=-70.0, v_threshold_mV=-50.0,
                          dtype=torch.float32)  # fmt: skip
    expected = [[0.0, 1.0, 0.0, 0.25], [1.0, 0.0, 0.0, 0.25], [0.5, 0.0, 1.0, 0.25]]
    torch.testing.assert_close(x, torch.tensor([expected]), atol=0, rtol=0)
    assert input_width(INPUTS) == 4
    assert make_agent("tdrqn", 3, 20, SMOKE.agent.sizes, inputs=INPUTS).lstm.lstm.input_size == 4


def test_a_run_with_a_registered_feature_trains_saves_and_plays(tmp_path):
    config = SMOKE.with_changes({"agent.sizes.inputs": list(INPUTS),
                                 "train.total_env_steps": 6 * 20 * 8,
                                 "train.eval_every_episodes": 16})  # fmt: skip
    assert config.agent.sizes.inputs == INPUTS
    rows = train(config, tmp_path / "run")
    assert rows and all(np.isfinite(row["val_return"]) for row in rows)
    saved = json.loads((tmp_path / "run" / "config.json").read_text())
    assert saved["agent"]["sizes"]["inputs"] == list(INPUTS)
    assert Experiment.from_dict(saved) == config
    network = load_agent(tmp_path / "run")
    assert network.sizes.inputs == INPUTS and network.lstm.lstm.input_size == 4
    assert len(read_metrics(tmp_path / "run")) == len(rows)
    from spikectl.contexts import make_splits

    contexts = make_splits(2, 1, seed=3, n_val=0, n_neurons=5, episode_length=20)[0]
    episodes = evaluate_policy(contexts, GreedyController(network))
    assert episodes.returns.shape == (2,)
    # The compiled forward computes only its own four features.
    with pytest.raises(ValueError, match="this network reads target, step-fraction"):
        CompiledPolicy.from_network(network)


def test_the_names_are_checked_in_one_line():
    unknown = (
        r"^AgentSizes.inputs: unknown input feature 'nearness'; this spikectl has "
        r"target, target-voltage, others-spiking, proximity"
    )
    with pytest.raises(ConfigError, match=unknown):
        dataclasses.replace(SMOKE.agent.sizes, inputs=("nearness",))
    with pytest.raises(ValueError, match="a taken name needs another name|already registered"):
        INPUT_FEATURES.register("target", STEP_FRACTION)
    with pytest.raises(ValueError, match="width must be an int >= 1"):
        InputFeature(0, step_fraction, "none")
    with pytest.raises(TypeError, match="target_in_input is now inputs=.*'target'"):
        make_agent("tdrqn", 5, 20, target_in_input=False)


@pytest.mark.parametrize(
    ("flags", "inputs"),
    [({}, ("target",)),
     ({"target_in_input": False}, ()),
     ({"target_voltage_in_input": True}, ("target", "target-voltage")),
     ({"target_in_input": False, "others_spiking_in_input": True, "proximity_in_input": True},
      ("others-spiking", "proximity"))],
)  # fmt: skip
def test_config_json_with_the_older_booleans_reads_as_their_features(flags, inputs):
    saved = SMOKE.to_dict()
    del saved["agent"]["sizes"]["inputs"]
    saved["agent"]["sizes"].update({"target_in_input": True, "target_voltage_in_input": False,
                                    "others_spiking_in_input": False,
                                    "proximity_in_input": False, **flags})  # fmt: skip
    assert Experiment.from_dict(saved).agent.sizes.inputs == inputs


def test_config_json_files_of_earlier_versions_read_back():
    from pathlib import Path

    run = Path(__file__).parent / "data" / "format2-smoke-run" / "config.json"
    assert Experiment.from_dict(json.loads(run.read_text())).agent.sizes.inputs == ("target",)
    quick = PRESETS["quick"].to_dict()
    quick["agent"]["sizes"]["target_voltage_in_input"] = True
    with pytest.raises(ConfigError, match="inputs and the older target_voltage_in_input "
                                          "cannot both be given"):  # fmt: skip
        Experiment.from_dict(quick)
    del quick["agent"]["sizes"]["inputs"]
    assert Experiment.from_dict(quick) == PRESETS["quick"]
    with pytest.raises(ValueError, match="unknown config field"):  # no old name in the API
        SMOKE.with_changes({"agent.sizes.target_voltage_in_input": True})
