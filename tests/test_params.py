"""NeuronParams: defaults from Table 1, derived quantities, validation."""

from __future__ import annotations

import dataclasses

import pytest

from spikectl import NeuronParams
from spikectl.neuron.params import NEVER_RELEASES


def test_defaults_are_table_1():
    params = NeuronParams()
    assert params.v_rest_mV == -70.0 and params.v_threshold_mV == -50.0
    assert params.membrane_time_constant_ms == pytest.approx(20.0)
    assert params.stimulus_current_pA / params.capacitance_pF == 40.0
    assert params.synaptic_current_pA / params.capacitance_pF == 20.0
    assert params.min_release_interval_steps == 5


def test_release_interval_follows_the_rule():
    # p_r (1 - exp(-k / tau_R)) >= 0.5: with p_r = 1 and tau_R = 3, k >= 3 ln 2 = 2.08.
    assert NeuronParams(release_scale=1.0).min_release_interval_steps == 3
    assert NeuronParams(vesicle_recovery_ms=1.0).min_release_interval_steps == 2
    assert NeuronParams(release_scale=0.49).min_release_interval_steps == NEVER_RELEASES


def test_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        NeuronParams().v_rest_mV = 0.0


def test_dict_round_trip():
    params = NeuronParams(release_scale=0.8, refractory_steps=2)
    assert NeuronParams.from_dict(params.to_dict()) == params
    with pytest.raises(ValueError, match="unknown NeuronParams field"):
        NeuronParams.from_dict({"v_rest": -70})


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"v_threshold_mV": -80.0}, "above v_rest_mV"),
        ({"capacitance_pF": 0.0}, "capacitance_pF must be > 0"),
        ({"resistance_GOhm": -1.0}, "resistance_GOhm must be > 0"),
        ({"release_scale": 1.5}, "release_scale"),
        ({"refractory_steps": 1.5}, "refractory_steps"),
        ({"refractory_steps": -1}, "refractory_steps"),
        ({"stimulus_current_pA": -1.0}, "stimulus_current_pA"),
        ({"dt_ms": 50.0}, "overshoot"),
        ({"v_rest_mV": float("nan")}, "finite"),
    ],
)
def test_invalid_values_name_the_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        NeuronParams(**kwargs)


def test_non_numbers_are_rejected():
    with pytest.raises(TypeError, match="v_rest_mV must be a number"):
        NeuronParams(v_rest_mV="-70")


def test_derived_quantities_have_the_model_values_and_are_not_fields():
    params = NeuronParams()
    assert params.stimulus_step_mV == 40.0 and params.synaptic_step_mV == 20.0
    assert params.voltage_step_mV(300.0) == 10.0
    assert params.leak_per_step == params.dt_ms / params.membrane_time_constant_ms
    assert params.v_spike_mV == -50.0 - 1e-6
    assert params.recovery_per_step == 1.0 / 3.0
    # Properties are not saved: to_dict holds exactly the fields, as before.
    assert list(params.to_dict()) == [field.name for field in dataclasses.fields(NeuronParams)]
    assert "leak_per_step" not in params.to_dict()
