"""One interface for everything that acts: trained agents, planners and the references.

A *controller* has ``reset()`` (a new episode starts) and ``act(observation, info) ->
int`` on one environment's observation and ``info`` (``info["action_mask"]``, and
``info["context_index"]`` for the privileged references that replay a known answer).
Its *batched form*, ``act_batch(observations, infos) -> int [S]``, acts on the
batched observations of a vector environment, one episode per sub-environment.
Controllers that carry state per episode and have no natural batch (the planners)
get one through :func:`batched`, which plays an independent copy per sub-environment.

The reference controllers live here: :class:`DoNothing`, :class:`RandomLegal` and
:class:`Witness`. The planners (``IdentifyAndPlan``, ``OraclePlanner``) are in
``spikectl.planning``, trained agents (``GreedyController``, ``CompiledPolicy``) in
``spikectl.agents``, and ``spikectl.load_controller`` builds any of them by name or
from a file. :func:`spikectl.envs.rollout.run_episodes`, ``spikectl evaluate``,
``spikectl baselines`` and the real-time rig (``spikectl realtime``) all play
controllers (docs/environment.md, "Controllers").
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping
from typing import Any, Protocol, runtime_checkable

import numpy as np

from spikectl.contexts import ContextSet
from spikectl.contexts.generation import check_seed
from spikectl.envs.env_support import random_legal_actions
from spikectl.envs.sensing import SPIKES_KEY
from spikectl.neuron.simulator import DO_NOTHING


@runtime_checkable
class Controller(Protocol):
    """What acts on one environment: a new episode starts at ``reset()``."""

    def reset(self) -> None: ...

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int: ...


@runtime_checkable
class BatchController(Controller, Protocol):
    """A controller with a batched form for the vector environment: ``reset()`` starts
    a new episode in every sub-environment, ``act_batch`` returns int64 [S]."""

    def act_batch(
        self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Any]
    ) -> np.ndarray: ...


class ControllerInputError(ValueError):
    """An observation or info given to a controller that no environment produces: not a
    dict, a key missing, NaN or infinite voltages, pattern values other than 0 and 1, an
    action mask that allows no action (the message names the controller and the entry).
    Every controller of this package raises it for the same inputs."""


def check_controller_input(
    observation: Any, info: Any, who: str, keys: tuple[str, ...] = ("voltage", "pattern")
) -> None:
    """Refuse what no environment produces, before a controller acts on it: a NaN
    voltage would otherwise be read as "no neuron near threshold" and a mask that allows
    nothing as "do nothing". Works on one environment's entries and on batched ones."""
    if not isinstance(observation, Mapping) or not isinstance(info, Mapping):
        raise ControllerInputError(
            f"{who}.act: observation and info must be dicts (as env.reset and env.step "
            f"return them), got {type(observation).__name__} and {type(info).__name__}"
        )
    # Spikes-only sensing (an extension) observes spikes in place of the voltages.
    missing = [key for key in keys if key not in observation
               and not (key == "voltage" and SPIKES_KEY in observation)]  # fmt: skip
    if "action_mask" not in info:
        missing.append("info['action_mask']")
    if missing:
        raise ControllerInputError(f"{who}.act: the observation lacks {missing}")
    try:
        voltage = np.asarray(observation.get("voltage", 0.0))
        pattern = np.asarray(observation.get("pattern", 0))
        mask = np.asarray(info["action_mask"])
        finite = bool(np.isfinite(voltage).all()) if "voltage" in keys else True
    except TypeError as error:
        raise ControllerInputError(f"{who}.act: an entry is not numeric: {error}") from None
    if not finite:
        raise ControllerInputError(f"{who}.act: the voltages hold NaN or infinite values")
    if "pattern" in keys and not _zeros_and_ones(pattern):
        raise ControllerInputError(f"{who}.act: the pattern holds values other than 0 and 1")
    if not _zeros_and_ones(mask):
        raise ControllerInputError(f"{who}.act: the action mask holds values other than 0 and 1")
    if mask.size == 0 or not mask.any(axis=-1).all():
        raise ControllerInputError(f"{who}.act: the action mask allows no action")


def _zeros_and_ones(values: np.ndarray) -> bool:
    """Whether every value is 0 or 1 (cheap for the bool and int8 arrays the
    environments give: a real-time rig calls this every decision)."""
    if values.dtype == np.bool_:
        return True
    if values.size == 0:
        return True
    if values.dtype.kind in "iu":
        return bool(values.min() >= 0 and values.max() <= 1)
    if values.dtype.kind != "f":
        return False
    return bool(((values == 0) | (values == 1)).all())


def _context_index(info: Mapping[str, Any], who: str) -> int:
    if "context_index" not in info:
        raise ValueError(
            f"{who} replays a known answer per context and needs info['context_index'] "
            "(the environment's info has it when a context comes from its ContextSet)"
        )
    return int(info["context_index"])


class DoNothing:
    """Never stimulate: scores exactly 0.5 on every context."""

    def reset(self) -> None:
        pass

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        return DO_NOTHING

    def act_batch(self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Any]):
        return np.full(np.shape(infos["action_mask"])[0], DO_NOTHING, dtype=np.int64)


class RandomLegal:
    """Uniformly random legal actions from a generator seeded once, with ``seed``."""

    def __init__(self, seed: int | None = None) -> None:
        if seed is not None:
            seed = check_seed(seed)
        self.rng = np.random.default_rng(seed)

    def reset(self) -> None:
        pass

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        check_controller_input(observation, info, "RandomLegal", ())
        mask = np.asarray(info["action_mask"], dtype=bool)[None]  # [1, n + 1]
        return int(random_legal_actions(mask, self.rng)[0])

    def act_batch(self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Any]):
        check_controller_input(observations, infos, "RandomLegal", ())
        return random_legal_actions(infos["action_mask"], self.rng)


class Witness:
    """Replay each context's witness (a privileged reference): return 1.0 where the
    dynamics are deterministic. The context comes from ``info["context_index"]`` into
    ``contexts``; actions are in the agent's indexing (observable neurons only)."""

    def __init__(self, contexts: ContextSet) -> None:
        if any(context.witness is None for context in contexts):
            raise ValueError("some contexts have no witness to replay")
        self.witnesses = np.stack([context.agent_witness for context in contexts]).astype(
            np.int64
        )  # [C, N]
        self.patterns = np.stack([context.pattern for context in contexts])  # [C, N]
        self.targets = np.array([context.observed_target for context in contexts])  # [C]

    def _check_context(self, contexts: np.ndarray, observations: Mapping[str, Any]) -> None:
        """Refuse a context index outside the set, or an observation of another context
        (a Witness built on another set would replay the wrong answer silently)."""
        if contexts.size and (contexts.min() < 0 or contexts.max() >= len(self.targets)):
            raise ControllerInputError(
                f"Witness.act: context index {contexts.tolist()} is outside its set of "
                f"{len(self.targets)} contexts: build the Witness on the environment's set"
            )
        pattern = np.asarray(observations["pattern"])
        target = np.asarray(observations["target"])
        if pattern.shape != self.patterns[contexts].shape or not (
            np.array_equal(pattern, self.patterns[contexts])
            and np.array_equal(target, self.targets[contexts])
        ):
            raise ControllerInputError(
                "Witness.act: the observation's target and pattern are not those of its "
                "context in the Witness's set: build the Witness on the environment's set"
            )

    def reset(self) -> None:
        pass

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        check_controller_input(observation, info, "Witness", ("pattern", "target", "step"))
        context = _context_index(info, "Witness")
        self._check_context(np.asarray(context), observation)
        return int(self.witnesses[context, int(observation["step"])])

    def act_batch(self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Any]):
        check_controller_input(observations, infos, "Witness", ("pattern", "target", "step"))
        if "context_index" not in infos:
            _context_index(infos, "Witness")  # the error naming what is missing
        contexts = np.asarray(infos["context_index"], dtype=np.int64)  # [S]
        self._check_context(contexts, observations)
        return self.witnesses[contexts, np.asarray(observations["step"], dtype=np.int64)]


class Copies:
    """The batched form of a single-environment controller: one independent copy per
    sub-environment, made from ``controller`` when the batch size is first seen (by
    ``controller.spawn(index)`` where it has one, e.g. to seed each copy apart, else
    a deep copy). ``reset()`` resets every copy."""

    def __init__(self, controller: Controller) -> None:
        self.controller = controller
        self.copies: list[Controller] = []

    def _spawn(self, index: int) -> Controller:
        spawn = getattr(self.controller, "spawn", None)
        return spawn(index) if spawn is not None else copy.deepcopy(self.controller)

    def reset(self) -> None:
        for controller in self.copies:
            controller.reset()

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        return self.controller.act(observation, info)

    def act_batch(self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Any]):
        size = np.shape(infos["action_mask"])[0]
        if len(self.copies) != size:
            self.copies = [self._spawn(index) for index in range(size)]
        actions = np.empty(size, dtype=np.int64)
        for index, controller in enumerate(self.copies):
            observation = {key: value[index] for key, value in observations.items()}
            info = {key: value[index] for key, value in infos.items() if _per_env(value, size)}
            actions[index] = controller.act(observation, info)
        return actions


def _per_env(value: Any, size: int) -> bool:
    return isinstance(value, np.ndarray) and value.ndim >= 1 and value.shape[0] == size


def batched(controller: Controller) -> BatchController:
    """``controller`` itself where it has ``act_batch``, else :class:`Copies` of it."""
    if not isinstance(controller, Controller):
        raise TypeError(
            f"{type(controller).__name__} is not a controller: it needs reset() and "
            "act(observation, info) -> int"
        )
    return controller if hasattr(controller, "act_batch") else Copies(controller)


def play_episode(env: Any, controller: Controller, context: int, seed: int | None = None):
    """One episode of ``controller`` on context ``context`` of a single environment:
    (actions [N], return). The simplest closed loop; the rig times the same loop."""
    controller.reset()
    observation, info = env.reset(seed=seed, options={"context": int(context)})
    actions: list[int] = []
    total, done = 0.0, False
    while not done:
        action = controller.act(observation, info)
        actions.append(action)
        observation, reward, terminated, truncated, info = env.step(action)
        total += reward
        done = terminated or truncated
    return np.array(actions, dtype=np.int64), total


def first_decision_refusal(env: Any, make: Callable[[], Controller]) -> str | None:
    """Why the controller ``make()`` makes cannot play the single environment ``env``, or
    None where it can: it is made and takes its first decision on the first context's
    first observation (a controller refuses, in one line, what it cannot be made for or
    cannot read: a ValueError, ControllerInputError and ConfigError among them)."""
    observation, info = env.reset(options={"context": 0})
    try:
        controller = make()
        controller.reset()
        controller.act(observation, info)
    except ValueError as error:
        return " ".join(str(error).split())
    return None


__all__ = [
    "BatchController", "Controller", "ControllerInputError", "Copies", "DoNothing",
    "RandomLegal", "Witness", "batched", "check_controller_input", "first_decision_refusal",
    "play_episode",
]  # fmt: skip
