"""The batched twin of :class:`~spikectl.envs.env.NeuronControlEnv`: all networks in one call.

``step`` advances every sub-environment with a single :func:`spikectl.neuron.simulator.advance`
on a [num_envs, n, n] weight batch; rewards, observations, infos and autoresets are
array operations. It behaves exactly like a ``gymnasium.vector.SyncVectorEnv`` of single
environments (same seeds, same contexts, same autoreset), only faster.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from spikectl.contexts import Context
from spikectl.contexts.generation import is_int
from spikectl.envs import render as rendering
from spikectl.envs.env_arguments import (
    TARGET_RULE,
    bad_actions_message,
    bad_shape_message,
    batch_reset_options,
    context_choices,
    seed_list,
)
from spikectl.envs.env_support import (
    RENDER_FPS,
    RENDER_MODES,
    ContextsArgument,
    ContextTables,
    LegalActionBatchSpace,
    check_context,
    check_context_index,
    observation_space,
    resolve_setup,
)
from spikectl.envs.latency import ActionDelay
from spikectl.envs.sensing import Recording, make_observation
from spikectl.files import check_fits_in_memory
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.opsin import OpsinActuator
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import (
    DO_NOTHING,
    DrawnInputs,
    SimulatorState,
    advance,
    uniform_neuron_parameters,
)


class NeuronControlVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`~spikectl.envs.env.NeuronControlEnv` stepped as one batch.

    Takes ``num_envs`` plus the single environment's arguments; spaces are the single
    ones batched. Actions: int array [num_envs]. Infos: ``action_mask`` int8 [num_envs, n + 1],
    ``context_index`` [num_envs] (-1 for a passed ``Context``), ``spikes`` [num_envs, n]
    and ``target_spiked`` [num_envs], each with Gymnasium's ``_key`` mask of the
    sub-environments that report it (after an autoreset there are no spikes).

    Autoreset is ``AutoresetMode.NEXT_STEP``: a sub-environment that terminated is reset
    by the next ``step``, which ignores its action and returns its first observation,
    reward 0 and ``terminated`` False.

    Seeding matches ``SyncVectorEnv``: each sub-environment has its own generator;
    ``reset(seed=s)`` seeds sub-environment i with ``s + i`` (a list gives one seed each),
    and contexts are drawn from it with ``integers(len(contexts))``.

    Reset options: ``{"context": c}`` with c an index or ``Context`` for every
    sub-environment, or a sequence of num_envs of them (evaluate a whole set in one
    batch); ``{"reset_mask": bool array [num_envs]}`` resets only the marked ones.

    Extensions (``extensions=``, docs/extensions.md) behave as in the single
    environment; their random numbers come from each sub-environment's generator in
    the single environment's order, so the batch still equals ``SyncVectorEnv``.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": RENDER_FPS,
                "autoreset_mode": AutoresetMode.NEXT_STEP}  # fmt: skip
    autoreset_mode = AutoresetMode.NEXT_STEP  # as Gymnasium's vector envs say it; TorchRL reads it

    def __init__(
        self,
        num_envs: int = 1,
        n_neurons: int | None = None,
        episode_length: int | None = None,
        contexts: ContextsArgument = None,
        split: str = "train",
        params: NeuronParams | None = None,
        render_mode: str | None = None,
        extensions: Extensions | Mapping[str, Any] | None = None,
    ) -> None:
        if not is_int(num_envs) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        self.contexts, self.params, self.extensions, self._tables, self._effects = resolve_setup(
            contexts, split, n_neurons, episode_length, params, extensions, render_mode
        )
        self.num_envs = batch = int(num_envs)
        self.n_neurons = n = self.contexts.n_neurons
        self.n_observed = k = self.contexts.n_observed
        self.episode_length = length = self.contexts.episode_length
        self.render_mode = render_mode
        # Weights, per-step input buffers and state of every sub-environment, checked
        # before any is allocated (num_envs=10**9 is one line, not a frozen machine).
        check_fits_in_memory(batch * (16 * n * n + 16 * length * n + 64 * n),
                             f"num_envs={batch:,} environments of {n} neurons",
                             "use fewer environments")  # fmt: skip
        # The extensions' per-step draws, filled in place before each step.
        self._drawn = DrawnInputs(*self._effects.input_buffers(batch, n))
        self._opsin = OpsinActuator.for_environment(self.extensions, self.params, batch, n)

        self._delay = ActionDelay(batch, self.extensions.latency_steps)  # loop latency
        self._spikes_only = spikes_only = self.extensions.spikes_only  # not potentials
        self._spikes = np.zeros((batch, k), dtype=np.int8)  # the last step's (spikes-only)
        self._recording = Recording.of(self.extensions, batch, k)  # None: all recorded
        self.single_observation_space = observation_space(
            k, length, self._delay.steps, spikes_only, self._recording is not None
        )
        self.single_action_space = spaces.Discrete(k + 1, start=DO_NOTHING)
        self.observation_space = batch_space(self.single_observation_space, batch)
        self.action_space = LegalActionBatchSpace(batch, k)

        self._rngs: list[np.random.Generator | None] = [None] * batch
        self._envs = np.arange(batch)
        self._state = SimulatorState.at_rest(batch, n, self.params)
        self._weights = np.zeros((batch, n, n), dtype=np.float64)
        self._neurons: np.ndarray | None = None  # [num_envs, 2, n] for heterogeneous neurons
        if self._tables.neurons is not None:
            self._neurons = uniform_neuron_parameters(self.params, batch, n)
        self._observable = (
            None if self._tables.observable is None else np.zeros((batch, k), dtype=np.int64)
        )
        self._targets = np.zeros(batch, dtype=np.int64)  # neuron indices
        self._observed_targets = np.zeros(batch, dtype=np.int64)  # the agent's indices
        self._patterns = np.zeros((batch, length), dtype=np.int8)
        self._reward_if_spike = np.zeros((batch, length), dtype=np.float64)
        self._reward_if_silent = np.zeros((batch, length), dtype=np.float64)
        self._legal = self.action_space.legal  # shared, so sample() follows every reset
        self._context_index = np.full(batch, -1, dtype=np.int64)
        self._next_step = np.full(batch, length, dtype=np.int64)
        self._last_action = np.full(batch, DO_NOTHING, dtype=np.int64)
        self._voltage = np.full((batch, k), self.params.v_rest_mV, dtype=np.float32)
        self._needs_reset = np.zeros(batch, dtype=bool)
        self._any_needs_reset = False
        self._all_envs = np.ones(batch, dtype=bool)
        # Offsets of each env's rows in the flattened per-env tables.
        self._first_cells = self._envs * length
        self._first_legal = self._envs * (k + 1)
        self._target_cells = self._envs * n
        self._actions = np.full((batch, 1), DO_NOTHING, dtype=np.int64)  # neuron indices
        self._agent_actions = np.zeros(batch, dtype=np.int64)  # with hidden neurons or latency
        self._indirect = self._observable is not None or self._delay.steps > 0
        self._out_voltage = np.zeros((batch, 1, n), dtype=np.float64)
        self._out_spikes = np.zeros((batch, 1, n), dtype=bool)
        # The episode as the agent sees it: the actions that landed, the observable spikes.
        self._action_history = np.full((batch, length), DO_NOTHING, dtype=np.int64)
        self._spike_history = np.zeros((batch, length, k), dtype=bool)
        self._ever_reset = np.zeros(batch, dtype=bool)
        self._all_reset = False

    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Reset every sub-environment (``seed``: one seed, or one per sub-environment) and
        return the batched ``(observations, infos)``. A seed that is not None, an integer
        >= 0 or a list of num_envs of them is a ``SeedError``.
        """
        seeds = seed_list(seed, self.num_envs)
        if is_int(seed):
            super().reset(seed=int(seed))
        which, choice = batch_reset_options(options, self.num_envs)
        envs = np.flatnonzero(which)
        for i in envs:
            if seeds[i] is not None or self._rngs[i] is None:
                self._rngs[i] = seeding.np_random(seeds[i])[0]
        self._reset_envs(envs, context_choices(choice, envs, self.num_envs))
        self._needs_reset[which] = False
        self._any_needs_reset = bool(self._needs_reset.any())
        self._ever_reset |= which
        self._all_reset = bool(self._ever_reset.all())
        infos = {
            "action_mask": self._legal.astype(np.int8),
            "_action_mask": which.copy(),
            "context_index": self._context_index.copy(),
            "_context_index": which.copy(),
        }
        return self._observation(self._voltage.copy()), infos

    def step(
        self, actions: np.ndarray
    ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Step every sub-environment with its action ([S] ints, -1 does nothing); finished
        sub-environments reset themselves on the next step (Gymnasium's next-step autoreset).

        Returns batched ``(observations, rewards, terminated, truncated, infos)``.
        """
        if not self._all_reset:
            never = np.flatnonzero(~self._ever_reset).tolist()
            raise ResetNeeded(f"sub-environment(s) {never} were never reset: call reset() first")
        actions = self._checked_actions(actions)
        autoreset = self._needs_reset
        effects = self._effects
        # With latency the actions chosen latency_steps ago land (an autoreset: none).
        landing = self._delay.push(actions)
        if self._delay.steps and self._any_needs_reset:
            landing[autoreset] = DO_NOTHING
        if self._observable is not None:  # the agent's indices -> neuron indices
            self._actions[:, 0] = np.where(
                landing >= 0, self._observable[self._envs, np.maximum(landing, 0)], DO_NOTHING
            )
        elif self._delay.steps:
            self._actions[:, 0] = landing
        if effects.random_dynamics:
            self._draw_inputs(np.flatnonzero(~autoreset))
        # With the opsin (an extension) the light's current is the stimulus, not the pulse.
        stimulus = self._actions if self._opsin is None else self._opsin.illuminate(
            self._state.voltage_mV, self._actions, self._drawn.input_mV)  # fmt: skip
        advance(self._state, self._weights, stimulus, self.params, self._out_voltage,
                self._out_spikes, self._neurons, self._drawn)  # fmt: skip
        length = self.episode_length
        # Flat index of each env's current step into its [num_envs * N] tables; an env
        # about to autoreset points at its last step, which its reset then clears.
        cells = self._first_cells + np.minimum(self._next_step, length - 1)
        spikes = self._out_spikes[:, 0]
        target_spiked = spikes.reshape(-1).take(self._target_cells)
        rewards = np.where(
            target_spiked,
            self._reward_if_spike.reshape(-1).take(cells),
            self._reward_if_silent.reshape(-1).take(cells),
        )
        voltage = self._out_voltage[:, 0]
        if self._observable is not None:
            spikes = np.take_along_axis(spikes, self._observable, axis=1)
            voltage = np.take_along_axis(voltage, self._observable, axis=1)
        self._action_history.reshape(-1)[cells] = landing
        self._spike_history.reshape(-1, self.n_observed)[cells] = spikes
        self._next_step += 1
        self._last_action[:] = actions
        terminated = self._next_step == length
        spikes = spikes.copy()
        if effects.plain:
            self._voltage[:] = voltage
        else:
            steps = np.minimum(self._next_step, length)
            self._voltage[:] = effects.observe(voltage, steps, self._noise(~autoreset))
        if self._any_needs_reset:
            # Their networks were stepped with "do nothing" along with the rest; reset now.
            resetting = np.flatnonzero(autoreset)
            self._reset_envs(resetting, [None] * resetting.size)
            rewards[autoreset] = 0.0
            terminated[autoreset] = False
            target_spiked[autoreset] = False
            spikes[autoreset] = False
        # An autoreset environment's: none; an unrecorded neuron's (an extension): none.
        self._spikes[:] = spikes if self._recording is None else self._recording.sense(spikes)
        active = ~autoreset
        self._needs_reset = terminated.copy()
        self._any_needs_reset = bool(terminated.any())
        infos = {
            "action_mask": self._legal.astype(np.int8),
            "_action_mask": self._all_envs.copy(),
            "context_index": self._context_index.copy(),
            "_context_index": self._all_envs.copy(),
            "spikes": spikes,
            "_spikes": active,
            "target_spiked": target_spiked,
            "_target_spiked": active.copy(),
        }
        observation = self._observation(self._voltage.copy())
        return observation, rewards, terminated, np.zeros(self.num_envs, dtype=bool), infos

    def _checked_actions(self, actions: Any) -> np.ndarray:
        """Copy valid actions into the simulator's input; autoresetting envs do nothing."""
        array = np.asarray(actions)
        if array.shape != (self.num_envs,) or array.dtype.kind not in "iu":
            raise ValueError(bad_shape_message(array, self.num_envs, "integers"))
        # The agent's actions: without hidden neurons or latency the simulator's input itself.
        checked = self._agent_actions if self._indirect else self._actions[:, 0]
        checked[:] = array
        if self._any_needs_reset:
            checked[self._needs_reset] = DO_NOTHING
        k = self.n_observed
        if checked.min() < DO_NOTHING or checked.max() >= k:
            raise ValueError(bad_actions_message(
                array, (checked < DO_NOTHING) | (checked >= k), "are out of range",
                f"actions are -1 (do nothing) or a neuron in 0..{k - 1} other than the target",
            ))  # fmt: skip
        legal = self._legal.reshape(-1).take(self._first_legal + checked + 1)
        if not legal.all():
            raise ValueError(bad_actions_message(
                array, ~legal, "are illegal", f'{TARGET_RULE} (see info["action_mask"]; '
                "extensions={'allow_target_action': True} allows it)",
            ))  # fmt: skip
        return checked

    def _draw_inputs(self, envs: np.ndarray) -> None:
        """Release uniforms and background input of ``envs`` for one step, each from its
        own generator in the single environment's order."""
        release, background = self._drawn
        for i in envs:
            self._effects.draw_inputs(self._rngs[i], None if release is None else release[i, 0],
                                      None if background is None else background[i, 0])  # fmt: skip

    def _noise(self, which: np.ndarray) -> np.ndarray | None:
        """Standard normal measurement noise [num_envs, k] for the marked envs (0 elsewhere)."""
        if self._effects.noise_mV == 0:
            return None
        noise = np.zeros((self.num_envs, self.n_observed))
        for i in np.flatnonzero(which):
            noise[i] = self._rngs[i].standard_normal(self.n_observed)
        return noise

    def _observation(self, voltage: np.ndarray) -> dict[str, np.ndarray]:
        return make_observation(
            self._spikes.copy() if self._spikes_only else voltage, self._spikes_only,
            self._observed_targets.copy(), self._patterns.copy(), self._next_step.copy(),
            self._last_action.copy(), self._delay.in_flight.copy() if self._delay.steps else None,
            None if self._recording is None else self._recording.mask.copy(),
        )  # fmt: skip

    def _reset_envs(self, envs: np.ndarray, choices: Sequence[int | Context | None]) -> None:
        """Put ``envs`` at rest with a new context each; draws go to each env's own generator."""
        rows = np.empty(envs.size, dtype=np.int64)
        passed: list[tuple[int, Context]] = []
        for k, (i, choice) in enumerate(zip(envs, choices, strict=True)):
            if choice is None:
                rows[k] = self._rngs[i].integers(len(self.contexts))
            elif isinstance(choice, Context):
                check_context(choice, self.n_neurons, self.episode_length, self.n_observed)
                rows[k] = -1
                passed.append((i, choice))
            else:
                try:
                    rows[k] = check_context_index(choice, len(self.contexts))
                except ValueError as error:
                    raise ValueError(f"env {i}: {error}") from None
        indexed = rows >= 0
        self._load(envs[indexed], self._tables, rows[indexed])
        self._context_index[envs] = rows
        for i, context in passed:
            tables = ContextTables.build([context], self.extensions.allow_target_action,
                                         self.params)  # fmt: skip
            self._load(np.array([i]), tables, 0)
        if self._recording is not None:  # each env's draw after its context, as the single's
            self._recording.draw([self._rngs[i] for i in envs], envs, self._observed_targets[envs])
        which = np.zeros(self.num_envs, dtype=bool)
        which[envs] = True
        self._state.reset(which, self.params)
        if self._opsin is not None:
            self._opsin.reset(which)
        self._next_step[envs] = 0
        self._last_action[envs] = DO_NOTHING
        self._voltage[envs] = self.params.v_rest_mV
        self._spikes[envs] = 0
        if not self._effects.plain:
            noise = self._noise(which)
            self._voltage[envs] = self._effects.observe(
                self._voltage[envs], 0, None if noise is None else noise[envs]
            )
        self._action_history[envs] = DO_NOTHING
        self._spike_history[envs] = False
        self._delay.clear(envs)

    def _load(self, envs: np.ndarray, tables: ContextTables, rows: np.ndarray | int) -> None:
        self._weights[envs] = tables.weights[rows]
        self._targets[envs] = tables.targets[rows]
        self._observed_targets[envs] = tables.observed_targets[rows]
        self._target_cells[envs] = envs * self.n_neurons + tables.targets[rows]
        self._patterns[envs] = tables.patterns[rows]
        self._reward_if_spike[envs] = tables.reward_if_spike[rows]
        self._reward_if_silent[envs] = tables.reward_if_silent[rows]
        self._legal[envs] = tables.legal[rows]
        if self._observable is not None:
            self._observable[envs] = tables.observable[rows]
        if tables.neurons is not None and self._neurons is None:  # a passed Context
            self._neurons = uniform_neuron_parameters(self.params, self.num_envs, self.n_neurons)
        if self._neurons is not None:
            self._neurons[envs] = (
                uniform_neuron_parameters(self.params, 1, self.n_neurons)
                if tables.neurons is None
                else tables.neurons[rows]
            )

    def render(self) -> tuple[str, ...] | tuple[np.ndarray, ...] | None:
        """One frame (or text raster) per sub-environment, as Gymnasium's vector wrappers expect."""
        if not rendering.can_render(self.render_mode, self._all_reset, "gymnasium.make_vec"):
            return None
        return rendering.render_batch(
            self.render_mode, self._patterns, self._action_history, self._spike_history,
            self._observed_targets, self._next_step,
        )  # fmt: skip
