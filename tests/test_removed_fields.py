"""Fields earlier versions' config.json files hold that spikectl no longer has: read
back where they hold the value under which the run ran as today's, refused in one line
otherwise (``Experiment.from_dict``)."""

from __future__ import annotations

import pytest

from spikectl.config_errors import ConfigError
from spikectl.training.config import Experiment
from spikectl.training.presets import PRESETS, SMOKE


@pytest.mark.parametrize("name", ["belief_in_input", "advice_in_input"])
def test_a_removed_agent_input_reads_back_off_and_is_refused_on(name):
    saved = SMOKE.to_dict()
    saved["agent"]["sizes"][name] = False
    assert Experiment.from_dict(saved) == SMOKE
    saved["agent"]["sizes"][name] = True
    with pytest.raises(ConfigError, match=f"^{name} is no longer in spikectl .*docs/results/"):
        Experiment.from_dict(saved)


def test_the_removed_asymmetric_critic_reads_back_off_and_is_refused_on():
    guided = PRESETS["guided"]
    saved = guided.to_dict()
    saved["learner"]["asymmetric_critic"] = False
    assert Experiment.from_dict(saved) == guided
    saved["learner"]["asymmetric_critic"] = True
    with pytest.raises(ConfigError, match="^asymmetric_critic is no longer in spikectl .*"
                                          "asymmetric-critic"):  # fmt: skip
        Experiment.from_dict(saved)
    with pytest.raises(ValueError, match="unknown DQNConfig field"):  # never a DQN field
        Experiment.from_dict({"learner": {"name": "dqn", "asymmetric_critic": False}})
