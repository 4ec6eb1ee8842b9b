"""Settling stochastic releases from the next step's residuals (spikectl.planning.release):
posteriors on hand-built cases, computed here by hand, and on stochastic-release networks
every settled release is the environment's and every known weight is the network's. And
the policy's use of unrested inputs under stochastic release, on hand-built networks."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import play_by_hand

from spikectl.contexts import make_splits
from spikectl.envs.env import NeuronControlEnv
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.planning import (
    Composition,
    IdentifyAndPlan,
    ObservationSettings,
    named_composition,
)
from spikectl.planning import observing as observing_module
from spikectl.planning.release import (
    SETTLED,
    exact_residuals,
    release_posterior,
    settled_releases,
)

PARAMS = NeuronParams()
TASK_MODEL = Composition("task-model", observation=ObservationSettings(task_model=True))
N = 4


def probabilities(plus: dict, minus: dict | None = None, prior: float = 0.0):
    """[N, N] P(+1), P(-1): ``prior`` everywhere (excitatory), the given entries set."""
    excites = np.full((N, N), prior)
    inhibits = np.zeros((N, N))
    for (i, j), value in plus.items():
        excites[i, j] = value
    for (i, j), value in (minus or {}).items():
        inhibits[i, j], excites[i, j] = value, 0.0
    return excites, inhibits


def test_a_known_synapse_settles_a_lone_release_either_way():
    chances = np.array([0.0, 0.6, 0.0, 0.0])
    excites, inhibits = probabilities({(1, 2): 1.0})
    observed = np.array([True, False, True, True])  # the spiking neuron is refractory
    arrived = release_posterior(chances, np.array([0.0, 0, 1, 0]), observed, excites, inhibits)
    failed = release_posterior(chances, np.array([0.0, 0, 0, 0]), observed, excites, inhibits)
    floor = 1e-3  # release.FLOOR: a confident synapse weakens a combination, never rules it out
    assert arrived[1] == pytest.approx(0.6 / (0.6 + 0.4 * floor))
    assert failed[1] == pytest.approx(0.6 * floor / (0.6 * floor + 0.4))
    assert arrived[[0, 2, 3]].tolist() == [0, 0, 0]


def test_an_unknown_row_with_no_residual_stays_uncertain_by_its_prior():
    """Nothing arrived: either no release, or a release onto no synapse (each absent
    with probability 1 - p): P(released) = c prod(1 - p) / (c prod(1 - p) + 1 - c)."""
    c, p = 0.5, 0.3
    chances = np.array([c, 0.0, 0.0, 0.0])
    excites, inhibits = probabilities({}, prior=p)
    posterior = release_posterior(chances, np.zeros(N), np.array([False, True, True, True]),
                                  excites, inhibits)  # fmt: skip
    silent = (1 - p) ** 3
    assert posterior[0] == pytest.approx(c * silent / (c * silent + 1 - c))
    refractory0 = np.array([False, True, True, True])
    released, _, observed = settled_releases(chances, np.zeros(N), refractory0, excites, inhibits)
    assert SETTLED < posterior[0] < 1 - SETTLED
    assert not observed.any()  # every column its synapses may reach is withheld


def test_two_spikes_one_residual_each():
    """Neuron 0 is known to excite 2, neuron 1 to inhibit 3: residuals (+1 on 2, 0 on 3)
    say 0 released and 1 did not; both settle, and every column is kept."""
    chances = np.array([0.6, 0.5, 0.0, 0.0])
    excites, inhibits = probabilities({(0, 2): 1.0}, {(1, 3): 1.0})
    residual = np.array([0.0, 0.0, 1.0, 0.0])
    observed = np.array([False, False, True, True])
    released, _, kept = settled_releases(chances, residual, observed, excites, inhibits)
    assert released.tolist() == [1, 0, 0, 0]
    assert kept.tolist() == observed.tolist()


def test_two_spikes_onto_one_synapse_each_are_weighed_by_their_chances():
    """Both neurons surely excite 2, one of them arrived: P(0 released) = c0 (1 - c1) /
    (c0 (1 - c1) + (1 - c0) c1), and likewise for 1 (both or neither: the floor)."""
    c0, c1 = 0.6, 0.3
    chances = np.array([c0, c1, 0.0, 0.0])
    excites, inhibits = probabilities({(0, 2): 1.0, (1, 2): 1.0})
    only2 = np.array([False, False, True, False])
    posterior = release_posterior(chances, np.array([0.0, 0, 1, 0]), only2, excites, inhibits)
    floor = 1e-3
    only0, only1 = c0 * (1 - c1), (1 - c0) * c1
    total = only0 + only1 + floor * (c0 * c1 + (1 - c0) * (1 - c1))
    assert posterior[0] == pytest.approx((only0 + floor * c0 * c1) / total)
    assert posterior[1] == pytest.approx((only1 + floor * c0 * c1) / total)


def test_nothing_spiked_is_no_evidence_changed():
    chances = np.zeros(N)
    excites, inhibits = probabilities({}, prior=0.3)
    observed = np.array([True, False, True, True])
    released, residual, kept = settled_releases(chances, np.ones(N), observed, excites, inhibits)
    assert released.tolist() == [0, 0, 0, 0] and kept.tolist() == observed.tolist()


def test_exact_residuals_only_where_nothing_else_moves_the_potentials():
    assert exact_residuals(None) and exact_residuals(Extensions(stochastic_release=True))
    for other in ({"observation_noise_mV": 1.0}, {"hidden_neurons": 1}, {"threshold_spread": 0.1},
                  {"background_rate": 1.0}, {"bleaching_time_constant_steps": 100.0}):  # fmt: skip
        assert not exact_residuals(Extensions(stochastic_release=True, **other)), other


def test_on_stochastic_networks_every_settled_release_and_known_weight_is_true(monkeypatch):
    """Played on stochastic-release networks, each release the policy settles as
    arrived is one the environment drew, and each it settles as failed either failed or
    reached no synapse the residuals saw (the same evidence: nothing arrived); at each
    episode's end every weight the estimate calls known is the network's (with the
    release chance as evidence, about one in eight was wrong on the suite's validation
    networks)."""
    extensions = Extensions(stochastic_release=True)
    contexts, _ = make_splits(6, 1, 8, 60, seed=3)
    env = NeuronControlEnv(contexts=contexts, params=PARAMS, extensions=extensions)
    policy = IdentifyAndPlan(PARAMS, named_composition(extensions, 8), extensions=extensions)
    assert policy.composition.name == "stochastic" and policy.known_sd == 0.4
    settled = []  # (step acted on, posterior, chances, observed) of each settling
    real = observing_module.settled_releases
    acting = [0]  # the step the policy is acting on

    def record(chances, residual, observed, excites, inhibits):
        posterior = release_posterior(chances, residual, observed, excites, inhibits)
        settled.append((acting[0], posterior, np.asarray(chances).copy(), observed.copy()))
        return real(chances, residual, observed, excites, inhibits)

    monkeypatch.setattr(observing_module, "settled_releases", record)
    agree = {True: 0, False: 0}
    learned = 0
    for index, context in enumerate(contexts):
        observation, info = env.reset(seed=index, options={"context": index})
        policy.reset()
        truth = []
        settled.clear()
        for step in range(60):
            acting[0] = step
            observation, _, terminated, _, info = env.step(policy.act(observation, info))
            truth.append(env._state.released[0].copy())  # the releases of this step
            if terminated:
                break
        assert settled
        # Acting at step s, the policy reads the potentials after step s - 1, which carry
        # the releases of step s - 2.
        for acted_at, posterior, chances, observed in settled:
            released = truth[acted_at - 2]
            spiked = chances > 0
            arrived = spiked & (posterior >= 1 - SETTLED)
            failed = spiked & (posterior <= SETTLED)
            assert released[arrived].all()
            unseen = ~np.any(context.weights[:, observed] != 0, axis=1)  # [n]
            assert (~released[failed] | unseen[failed]).all()
            agree[True] += int(arrived.sum())
            agree[False] += int((failed & ~released).sum())
        signs, known = policy.estimate.weights(policy.known_sd)
        assert np.array_equal(signs[known], context.weights[known])
        learned += int(known.sum()) - 8  # the diagonal is known from the start
    assert agree[True] > 20 and agree[False] > 10  # both kinds settled, many times
    assert learned > 6 * 8  # more than a row's worth per network


def _play_by_hand(policy, weights, pattern, target, first_actions):
    """Plays ``policy`` on the deterministic simulator (what a stochastic run shows
    when every release arrives) with ``first_actions`` forced, and returns its action
    at the step after them."""
    steps = len(first_actions) + 1
    actions, fired = play_by_hand(policy, weights.astype(np.int8), target, pattern,
                                  first_actions, steps=steps)  # fmt: skip
    assert fired[1], "the release of step 0 reached the target"
    return actions[-1]


def test_an_unrested_known_input_is_stimulated_where_the_plan_misses_the_next_spike():
    """Neuron 0 is the target's only input (told); it released at step 0 and the target
    spiked at step 1. Spikes are wanted at steps 1 and 3: by the paper's rule neuron 0's
    vesicles are back only at step 5, so the plan misses step 3; under stochastic release
    it releases at step 2 with chance p_r (1 - exp(-2 dt / tau_R)) = 0.32, and the
    policy stimulates it (lab/planners' PlanUnderRelease follows the plan instead)."""
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 2] = 1
    pattern = np.zeros(60, dtype=np.int8)
    pattern[[1, 3]] = 1
    stochastic = Extensions(stochastic_release=True)
    policy = IdentifyAndPlan(composition=TASK_MODEL, extensions=stochastic, told_weights=weights)
    action = _play_by_hand(policy, weights, pattern, target=2, first_actions=[0, -1])
    assert action == 0
    # Without stochastic release the rule is exact: the input stays silent, no stimulus.
    paper = IdentifyAndPlan(told_weights=weights)
    assert _play_by_hand(paper, weights, pattern, target=2, first_actions=[0, -1]) == -1


def test_the_unrested_input_with_the_highest_release_chance_is_chosen():
    """Two inputs of the target, neuron 0 released at step 0 and neuron 1 at step 2
    (their chances at step 4: 0.48 and 0.32); a spike wanted at step 5 that the plan
    misses: neuron 0, whose vesicles have had longer."""
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 2] = weights[1, 2] = 1
    pattern = np.zeros(60, dtype=np.int8)
    pattern[[1, 3, 5]] = 1
    stochastic = Extensions(stochastic_release=True)
    policy = IdentifyAndPlan(composition=TASK_MODEL, extensions=stochastic, told_weights=weights)
    action = _play_by_hand(policy, weights, pattern, target=2, first_actions=[0, -1, 1, -1])
    assert action == 0
