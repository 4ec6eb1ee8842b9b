"""The Gymnasium environment (docs/environment.md): make one neuron spike a target pattern.

What the vector environment shares with :class:`NeuronControlEnv` (the context
tables, the reward formula, the spaces and the argument checks) lives in
``spikectl.envs.env_support``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.error import ResetNeeded

from spikectl.contexts import Context
from spikectl.envs import render as rendering
from spikectl.envs.env_arguments import check_seed
from spikectl.envs.env_support import (
    RENDER_FPS,
    RENDER_MODES,
    ContextsArgument,
    ContextTables,
    LegalActionSpace,
    as_action,
    check_context,
    check_context_index,
    observation_space,
    resolve_setup,
)
from spikectl.envs.latency import ActionDelay
from spikectl.envs.sensing import Recording, make_observation
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.opsin import OpsinActuator
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, DrawnInputs, SimulatorState, advance

__all__ = ["NeuronControlEnv"]


class NeuronControlEnv(gym.Env[dict[str, Any], int]):
    """
    ## Description

    Closed-loop control of a simulated network of leaky integrate-and-fire neurons
    with short-term synaptic depression (docs/model.md). In each episode a *context* fixes the
    hidden signed connectivity, a target neuron and a binary target pattern of N steps;
    the agent stimulates one (non-target) neuron per step, or none, so that the target
    spikes exactly when the pattern says. Every context carries a witness action sequence
    that reproduces its pattern, so the best return is always 1.

    ## Action Space

    `Discrete(n + 1, start=-1)`: -1 does nothing, j in 0..n-1 stimulates neuron j for one
    step (+40 mV; a refractory neuron ignores it). The target neuron is illegal unless
    `extensions={"allow_target_action": True}`; an illegal, out-of-range or non-integer
    action raises `ValueError`. This environment is strict: for clients that send any action of the
    space (Gymnasium's "sync"/"async" `make_vec` sample the batch without a mask), use
    the flat ids, `spikectl/NeuronControlFlat-v0` and its twins (docs/ecosystem.md).
    `info["action_mask"]` (int8, 1 = legal) marks the legal actions; `action_space.sample()`
    draws only legal ones, and so does Gymnasium's `sample(mask=info["action_mask"])`.
    With hidden neurons (an extension) the agent sees k < n neurons: every n below is
    then k, and index i means the i-th observable neuron (increasing neuron order,
    `Context.observable`).

    ## Observation Space

    A `Dict`; the connectivity is never observed.

    | key           | space                           | meaning                               |
    |---------------|---------------------------------|---------------------------------------|
    | `voltage`     | `Box(-inf, inf, (n,), float32)` | membrane potentials in mV (see below) |
    | `target`      | `Discrete(n)`                   | the neuron to control                 |
    | `pattern`     | `MultiBinary(N)` (int8)         | steps at which the target must spike  |
    | `step`        | `Discrete(N + 1)`               | index of the next step: 0 after reset |
    | `last_action` | `Discrete(n + 1, start=-1)`     | the previous action, -1 after reset   |

    Potentials are observed after integration and before reset, so a spike shows as
    >= -50 mV; after reset all are at rest (-70 mV). Measurement noise and
    photobleaching (extensions) change what is observed, never the dynamics.

    With loop latency (`extensions={"latency_steps": L}`, L in 1..5) an action chosen at
    step t stimulates at step t + L, and the observation has one more key,
    `actions_in_flight` (`MultiDiscrete`, int64 [L] in -1..n-1): the actions chosen at
    steps s - L .. s - 1 of the observation with step index s, oldest first, -1 before
    the episode. `last_action` stays the action chosen last; the action mask applies to
    the chosen action.

    With spikes-only sensing (`extensions={"sensing": "spikes"}`) `voltage` is replaced by
    `spikes` (`MultiBinary(n)`, int8): 1 for each neuron that spiked at the step just
    simulated (all 0 after reset). With `recorded_neurons` m as well, only m neurons are
    recorded per episode (the target and m - 1 drawn at reset): the others' spikes read 0,
    and `recorded` (`MultiBinary(n)`, int8) marks the recorded ones.

    ## Rewards

    With m spikes in the pattern, step t earns R_max/m if the target spikes and
    pattern[t] = 1, R_max/(N - m) if it is silent and pattern[t] = 0, else 0; R_max = 0.5.
    An episode's return lies in [0, 1]; doing nothing scores 0.5, the witness 1.

    ## Starting State

    Every neuron at rest (-70 mV) with no history; the context is drawn uniformly
    from the configured set with `self.np_random`, or chosen by `reset` options.

    ## Episode End

    Termination (never truncation) after step N - 1. Stepping again before `reset`
    raises `gymnasium.error.ResetNeeded`.

    ## Arguments

    | argument         | default   | meaning                                               |
    |------------------|-----------|-------------------------------------------------------|
    | `n_neurons`      | `None`    | n; None: the context set's, else 8                    |
    | `episode_length` | `None`    | N; None: the context set's, else 60                   |
    | `contexts`       | `None`    | a `ContextSet`, a path to a saved one, or a dict      |
    |                  |           | `{"n_train": 100, "n_test": 100, "seed": 0}` of the   |
    |                  |           | sets to generate (None: those defaults)               |
    | `split`          | `"train"` | generated set to play: `"train"` or `"test"`          |
    | `params`         | `None`    | `NeuronParams` of generated sets; None: the paper's   |
    | `render_mode`    | `None`    | `"ansi"` or `"rgb_array"`                             |
    | `extensions`     | `None`    | `Extensions` or a dict of its fields                  |

    `extensions` (docs/extensions.md) switches on measurement noise, photobleaching,
    stochastic release, background activity and the target as an action
    (`allow_target_action`); its context-level fields (hidden and heterogeneous
    neurons) are drawn with generated sets and otherwise come from the context set.
    All off is exactly the paper.

    Generated sets are `make_splits(n_train, n_test, n_neurons, episode_length, seed,
    params)` (cached, so many environments share them; the dict may also be a
    `spikectl.envs.GeneratedContexts`); with a context set given, `split` is unused and
    an explicit `n_neurons`, `episode_length` or `params` must agree with the set.

    `reset(options={"context": c})` plays context `c`: an index into the set or a
    `Context` of the same size. `info` holds `action_mask` (int8 [n + 1], index a + 1
    for action a), `context_index` (None for a passed `Context`) and, after a step,
    `spikes` (bool [n]) and `target_spiked`.

    ```python
    >>> import gymnasium as gym
    >>> import spikectl
    >>> env = gym.make("spikectl/NeuronControl-v0", contexts={"n_train": 10, "n_test": 10})
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(-1)

    ```

    ## Version History
    * v0: Initial version; the extensions (docs/extensions.md) off by default. The action
      mask is int8 (it was bool), what Gymnasium's masked sampling takes. The generated
      sets' sizes and seed are one argument, `contexts={"n_train", "n_test", "seed"}`
      (they were `n_train`, `n_test` and `context_seed`), and the target as an action
      is the extension alone (the `allow_target_action` argument is gone); the same
      arguments give the same environment.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": RENDER_FPS}

    def __init__(
        self,
        n_neurons: int | None = None,
        episode_length: int | None = None,
        contexts: ContextsArgument = None,
        split: str = "train",
        params: NeuronParams | None = None,
        render_mode: str | None = None,
        extensions: Extensions | Mapping[str, Any] | None = None,
    ) -> None:
        self.contexts, self.params, self.extensions, self._tables, self._effects = resolve_setup(
            contexts, split, n_neurons, episode_length, params, extensions, render_mode
        )
        self.n_neurons = n = self.contexts.n_neurons
        self.n_observed = k = self.contexts.n_observed
        self.episode_length = length = self.contexts.episode_length
        self.render_mode = render_mode
        # The extensions' per-step draws, filled in place before each step.
        self._drawn = DrawnInputs(*self._effects.input_buffers(1, n))
        self._opsin = OpsinActuator.for_environment(self.extensions, self.params, 1, n)
        self._plain = self._effects.plain  # observations are the potentials
        self._random_dynamics = self._effects.random_dynamics
        # Loop latency: the actions chosen but not yet applied (none without it).
        self._delay = ActionDelay(1, self.extensions.latency_steps)
        self._latency = self._delay.steps

        self.action_space = LegalActionSpace(k)
        self._spikes_only = self.extensions.spikes_only  # spikes observed, not potentials
        self._recording = Recording.of(self.extensions, 1, k)  # None: every neuron recorded
        self.observation_space = observation_space(
            k, length, self._latency, self._spikes_only, self._recording is not None
        )
        # Episode history, written by the simulator in place through per-step views.
        self._action_history = np.full((1, length), DO_NOTHING, dtype=np.int64)
        self._voltage_history = np.zeros((length, n), dtype=np.float64)
        self._spike_history = np.zeros((length, n), dtype=bool)
        self._make_step_views()
        self._state: SimulatorState | None = None
        self._next_step = length  # no episode until reset
        self._context_index: int | None = None

    def _make_step_views(self) -> None:
        self._step_views = [
            (
                self._action_history[:, t : t + 1],
                self._voltage_history[None, t : t + 1],
                self._spike_history[None, t : t + 1],
            )
            for t in range(self.episode_length)
        ]

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Start an episode: a context drawn from the set by the seeded generator, or the one
        ``options`` names (``{"context": index}`` or a :class:`~spikectl.contexts.Context`).

        Returns ``(observation, info)``; the neurons start at rest. ``seed``: None or an
        integer >= 0 (Python or NumPy); anything else is a ``SeedError``.
        """
        super().reset(seed=check_seed(seed))
        context = None if options is None else _context_option(options)
        if isinstance(context, Context):
            check_context(context, self.n_neurons, self.episode_length, self.n_observed)
            tables = ContextTables.build([context], self.extensions.allow_target_action,
                                         self.params)  # fmt: skip
            row, self._context_index = 0, None
        else:
            if context is None:
                context = self.np_random.integers(len(self.contexts))
            row = self._context_index = check_context_index(context, len(self.contexts))
            tables = self._tables
        self._weights = tables.weights[row : row + 1]
        self._target = int(tables.targets[row])  # a neuron index
        self._observed_target = int(tables.observed_targets[row])  # the agent's index
        self._observable = None if tables.observable is None else tables.observable[row]
        self._neurons = None if tables.neurons is None else tables.neurons[row : row + 1]
        self._pattern = tables.patterns[row]
        self._reward_if_spike = tables.reward_if_spike[row].tolist()
        self._reward_if_silent = tables.reward_if_silent[row].tolist()
        self._legal = tables.legal[row]
        self._legal_list = self._legal.tolist()
        self._mask = self._legal.astype(np.int8)  # info["action_mask"]: Gymnasium's int8
        self.action_space.legal_mask = self._mask
        self._state = SimulatorState.at_rest(1, self.n_neurons, self.params)
        if self._opsin is not None:
            self._opsin.reset()
        self._action_history.fill(DO_NOTHING)
        self._spike_history.fill(False)
        self._delay.clear()
        self._next_step = 0
        if self._recording is not None:  # drawn after the context, from the same generator
            self._recording.draw([self.np_random], np.zeros(1, np.int64), [self._observed_target])
        if self._spikes_only:  # nothing has spiked yet
            sensed = np.zeros(self.n_observed, dtype=np.int8)
        else:
            sensed = np.full(self.n_observed, self.params.v_rest_mV, dtype=np.float32)
            if not self._plain:
                sensed = self._observe(sensed, 0)
        observation = make_observation(
            sensed, self._spikes_only, self._observed_target, self._pattern.copy(), 0,
            DO_NOTHING, self._delay.in_flight[0].copy() if self._latency else None,
            self._recorded(),
        )  # fmt: skip
        info = {"action_mask": self._mask.copy(), "context_index": self._context_index}
        return observation, info

    def step(self, action: int) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        """Apply ``action`` (-1 does nothing, j stimulates neuron j) for one 1 ms step.

        Returns ``(observation, reward, terminated, truncated, info)`` as Gymnasium's
        ``Env.step``; an illegal action raises ``ValueError``.
        """
        t = self._next_step
        if t >= self.episode_length:
            raise ResetNeeded(
                "call reset() before step()"
                if self._state is None
                else "the episode has terminated: call reset() before step()"
            )
        if type(action) is not int:
            action = as_action(action)
        if action < DO_NOTHING or action >= self.n_observed or not self._legal_list[action + 1]:
            raise ValueError(self._illegal_action_message(action))
        actions, voltage, spikes = self._step_views[t]
        observable = self._observable
        # With latency the action chosen latency_steps steps ago stimulates now.
        landing = self._delay.push_one(action) if self._latency else action
        actions[0, 0] = landing if observable is None or landing < 0 else observable[landing]
        if self._random_dynamics:
            self._effects.draw_inputs(self.np_random, *self._drawn)
        if self._opsin is not None:  # the light's current is the stimulus, not the pulse
            actions = self._opsin.illuminate(self._state.voltage_mV, actions, self._drawn.input_mV)
        advance(self._state, self._weights, actions, self.params, voltage, spikes,
                self._neurons, self._drawn)  # fmt: skip
        spikes = self._spike_history[t]
        target_spiked = bool(spikes[self._target])
        reward = self._reward_if_spike[t] if target_spiked else self._reward_if_silent[t]
        self._next_step = t + 1
        voltage = self._voltage_history[t]
        if observable is not None:
            voltage, spikes = voltage[observable], spikes[observable]
        if self._spikes_only:
            recording = self._recording
            sensed = spikes.astype(np.int8) if recording is None else recording.sense(spikes, 0)
        else:
            sensed = voltage.astype(np.float32) if self._plain else self._observe(voltage, t + 1)
        observation = make_observation(
            sensed, self._spikes_only, self._observed_target, self._pattern.copy(), t + 1,
            action, self._delay.in_flight[0].copy() if self._latency else None,
            self._recorded(),
        )  # fmt: skip
        info = {
            "action_mask": self._mask.copy(),
            "context_index": self._context_index,
            "spikes": spikes.copy(),
            "target_spiked": target_spiked,
        }
        return observation, reward, t + 1 == self.episode_length, False, info

    def _recorded(self) -> np.ndarray | None:
        """The observation's ``recorded`` (int8 [k]), or None without a recorded subset."""
        return None if self._recording is None else self._recording.mask[0].copy()

    def _observe(self, voltage: np.ndarray, step: int) -> np.ndarray:
        """Observed potentials with measurement noise / photobleaching (extensions)."""
        noise = self._effects.draw_noise(self.np_random, self.n_observed)
        return self._effects.observe(voltage, step, noise)

    def _illegal_action_message(self, action: int) -> str:
        if DO_NOTHING <= action < self.n_observed:
            return (
                f"action {action} stimulates the target neuron {self._observed_target}, which "
                "is not a legal action (extensions={'allow_target_action': True} allows it)"
            )
        return (
            f"action {action} is out of range: actions are -1 (do nothing) or a neuron in "
            f"0..{self.n_observed - 1} other than the target {self._observed_target}"
        )

    def render(self) -> str | np.ndarray | None:
        """The episode so far: text for ``render_mode="ansi"``, an RGB array for
        ``"rgb_array"``; ``None`` with a warning without a render mode.
        """
        if not rendering.can_render(self.render_mode, self._state is not None, "gymnasium.make"):
            return None
        actions, spikes = self._action_history[0], self._spike_history
        if self._observable is not None:  # what the agent sees: the observable neurons
            actions, spikes = (
                _observed_actions(actions, self._observable),
                spikes[:, self._observable],
            )
        return rendering.render(
            self.render_mode,
            self._pattern,
            self._spike_history[:, self._target],
            actions,
            spikes,
            self._observed_target,
            self._next_step,
        )

    def __getstate__(self) -> dict[str, Any]:
        # The step views alias the history arrays; pickling would turn them into copies.
        state = self.__dict__.copy()
        del state["_step_views"]
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._make_step_views()


def _observed_actions(actions: np.ndarray, observable: np.ndarray) -> np.ndarray:
    """Simulator actions (neuron indices) as the agent's (indices among ``observable``)."""
    return np.where(actions >= 0, np.searchsorted(observable, actions), DO_NOTHING)


def _context_option(options: dict[str, Any]) -> Any:
    if not isinstance(options, Mapping):
        raise TypeError(
            f"options must be a dict such as {{'context': 3}} or None, got {type(options).__name__}"
        )
    unknown = set(options) - {"context"}
    if unknown:
        raise ValueError(f"unknown reset option(s) {sorted(unknown)}; the only option is 'context'")
    return options.get("context")
