"""``load_controller``: any controller of the library by name or from a file; and
``load_agent``, a run's trained network.

Every controller has the interface of :mod:`spikectl.envs.controller` (``reset()``,
``act(observation, info) -> int``; the batched ``act_batch`` directly or through
``batched``), so one call gives what ``spikectl evaluate``, ``spikectl baselines`` and
the real-time rig play:

```python
controller = spikectl.load_controller("runs/quick", model="best")  # the PyTorch network
controller = spikectl.load_controller("runs/quick", compiled=True)  # its compiled policy
controller = spikectl.load_controller("policy.npz")                 # an exported policy
controller = spikectl.load_controller("identify-and-plan", env=env)
```

The named controllers (those that need no training) are the :data:`CONTROLLERS`
registry; one :func:`register_controller` line adds one, which ``load_controller``,
``spikectl benchmark`` and ``spikectl realtime`` then play by name.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from spikectl.contexts import ContextSet
from spikectl.envs.controller import Controller, DoNothing, RandomLegal, Witness
from spikectl.file_kinds import FileKind, identify, refuse_other_kinds
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.planning.lit_search import planned_light
from spikectl.planning.named import named_composition
from spikectl.planning.oracle import DEFAULT_ORACLE_WIDTH, OraclePlanner
from spikectl.planning.policy import IdentifyAndPlan
from spikectl.registry import Registry, load_target


@dataclass(frozen=True)
class Played:
    """What a named controller is made for: the contexts played (None where only the
    neuron model is known), their neuron parameters (None: the paper's) and the
    environment's extensions (the measurement noise, whether the target is legal, ...)."""

    contexts: ContextSet | None
    params: NeuronParams | None
    extensions: Extensions


@dataclass(frozen=True)
class NamedController:
    """A controller that needs no training, as :data:`CONTROLLERS` holds it."""

    make: Callable[[Played, int], Controller] | str
    """``make(played, seed)`` -> a fresh controller (or ``"module:function"``, imported
    when the controller is first made)."""
    description: str
    """One line for help texts and docs."""
    privileged: bool = False
    """It reads the played context (``info["context_index"]``): it needs the contexts."""
    stochastic: bool = False
    """Its seed changes what it does (the benchmark averages it over seeds)."""


CONTROLLERS: Registry[NamedController] = Registry("controller")
"""The controllers that need no training, by name, in registration order."""


def register_controller(
    name: str,
    make: Callable[[Played, int], Controller] | str,
    description: str,
    *,
    privileged: bool = False,
    stochastic: bool = False,
) -> NamedController:
    """Register a controller under ``name`` for :func:`load_controller` and ``spikectl
    benchmark`` / ``realtime``: ``make(played, seed)`` builds it from a :class:`Played`;
    ``privileged`` ones need the contexts, ``stochastic`` ones are averaged over seeds."""
    return CONTROLLERS.register(name, NamedController(make, description, privileged, stochastic))


def do_nothing(played: Played, seed: int) -> Controller:
    return DoNothing()


def random_legal(played: Played, seed: int) -> Controller:
    return RandomLegal(seed)


def identify_and_plan(played: Played, seed: int, realtime: bool = False) -> Controller:
    # The environment's extensions and size choose the composition (planning/named.py).
    n_neurons = None if played.contexts is None else played.contexts.n_observed
    composition = named_composition(played.extensions, n_neurons, realtime=realtime)
    return IdentifyAndPlan(played.params, composition, extensions=played.extensions, seed=seed)


def identify_and_plan_realtime(played: Played, seed: int) -> Controller:
    return identify_and_plan(played, seed, realtime=True)


def oracle(played: Played, seed: int) -> Controller:
    return OraclePlanner(played.contexts, played.params, DEFAULT_ORACLE_WIDTH,
                         played.extensions.allow_target_action,
                         light_mW_per_mm2=planned_light(played.extensions))  # fmt: skip


def witness(played: Played, seed: int) -> Controller:
    return Witness(played.contexts)


register_controller("do-nothing", do_nothing, "stimulates nothing (the 0 of the normalised score)")
register_controller("random", random_legal, "a uniformly random legal action each step",
                    stochastic=True)  # fmt: skip
register_controller("identify-and-plan", identify_and_plan,
                    "identifies the network from what it observes and plans greedily")  # fmt: skip
register_controller("oracle", oracle, "plans with the played network known (the 1 of the "
                    "normalised score)", privileged=True)  # fmt: skip
register_controller("witness", witness, "replays each context's witness sequence (return 1)",
                    privileged=True)  # fmt: skip
register_controller("identify-and-plan-realtime", identify_and_plan_realtime,
                    "identify-and-plan's real-time form: its fast form re-planning at a "
                    "narrower beam")  # fmt: skip


def controller_sources() -> str:
    """What a controller source may be, for messages."""
    return (
        "a controller is a run directory, a compiled policy file (.npz from export_policy), "
        "an amortised belief's weights (.pt: AmortisedController, or with a policy "
        "trained on it: BeliefPolicyController) "
        f"or one of {', '.join(CONTROLLERS)}"
    )


MODEL_CHOICES = ("final", "best")
"""Which weights of a run to load: ``final`` (model.pt, else the last checkpoint) or
``best`` (best_model.pt, the evaluation with the highest validation return)."""


def load_agent(
    run_dir: str | os.PathLike, n_neurons: int | None = None, model: str = "final"
) -> Any:
    """The trained online network of a run, on CPU: ``model="final"`` loads model.pt
    (else the last checkpoint), ``model="best"`` loads best_model.pt (the network of the
    evaluation with the highest validation return).

    Both files load weights-only with their checksums verified; a damaged, foreign or
    crafted file, or weights holding NaN or infinite values, is a RunDirError.
    ``n_neurons`` builds the network for another network size (per-neuron architectures
    only; DRQN and DMDRQN refuse it when they run).
    """
    # PyTorch and the training stack load here, never for a compiled policy file or a
    # planner: a rig running those imports neither.
    from spikectl.agents import make_agent
    from spikectl.training.checkpoint import checkpoint_weights
    from spikectl.training.run_files import (
        BEST_MODEL_FILE,
        CHECKPOINT_FILE,
        MODEL_FILE,
        RunDirError,
        read_config,
    )
    from spikectl.training.torch_files import load_model_weights

    if model not in MODEL_CHOICES:
        raise ValueError(f"model must be one of {MODEL_CHOICES}, got {model!r}")
    run_dir = Path(run_dir)
    config = read_config(run_dir)
    network = make_agent(
        config.agent.arch, config.env.n_observed if n_neurons is None else n_neurons,
        config.env.episode_length, config.agent.sizes, params=config.env.params,
    )  # fmt: skip
    if model == "best":
        if not (run_dir / BEST_MODEL_FILE).exists():
            raise RunDirError(
                f"{run_dir} holds no {BEST_MODEL_FILE}: runs save one only when they have a "
                "validation set (n_val > 0), from their first evaluation on"
            )
        weights = load_model_weights(run_dir / BEST_MODEL_FILE)
    elif (run_dir / MODEL_FILE).exists():
        weights = load_model_weights(run_dir / MODEL_FILE)
    elif (run_dir / CHECKPOINT_FILE).exists():
        weights = checkpoint_weights(run_dir / CHECKPOINT_FILE)
    else:
        raise RunDirError(f"{run_dir} holds no trained weights ({MODEL_FILE} or {CHECKPOINT_FILE})")
    try:
        network.load_state_dict(weights)
    except RuntimeError as error:
        raise RunDirError(
            f"the weights in {run_dir} do not fit a {config.agent.arch} of the saved config: "
            f"{str(error).splitlines()[0]}"
        ) from error
    network.eval()
    return network


def load_controller(
    source: str | os.PathLike,
    *,
    model: str = "final",
    compiled: bool = False,
    per_environment: bool = False,
    env: Any = None,
    contexts: ContextSet | None = None,
    params: NeuronParams | None = None,
    seed: int = 0,
) -> Controller:
    """The controller ``source`` names: a run directory (its trained network,
    ``model="final"`` or ``"best"``; ``compiled=True`` for its compiled policy;
    ``per_environment=True`` to play each environment of a batch alone, with the actions
    the real-time rig takes on every CPU: ``GreedyController``), a
    compiled policy file (.npz from ``spikectl.agents.export_policy``), an amortised
    belief's weights (a ``.pt`` state dict: the
    :class:`~spikectl.agents.amortised_controller.AmortisedController` on it; with a
    policy trained on the belief, the
    :class:`~spikectl.agents.belief_policy.BeliefPolicyController`), or one of
    :data:`CONTROLLERS` (:func:`register_controller` adds one).

    The named ones are made from what is played (:class:`Played`): the neuron model,
    the environment's extensions (the measurement noise, whether stimulating the target
    is legal; identify-and-plan's observation model,
    :func:`~spikectl.planning.named.named_composition`), and the contexts (which
    the privileged ones, oracle and witness, need) from ``env`` (a ``NeuronControlEnv`` or
    ``NeuronControlVectorEnv``) where it is given, else from ``contexts``; the neuron
    model is then the contexts' own (``contexts.params``), and ``params`` serves where
    neither is given (identify-and-plan alone; None: the paper's). ``seed`` seeds the
    random controller and the networks identify-and-plan's QMDP draws (where its
    composition has QMDP; ``spikectl benchmark`` plays it at seed 0).
    """
    if model not in MODEL_CHOICES:
        raise ValueError(f"model must be one of {MODEL_CHOICES}, got {model!r}")
    name = os.fspath(source)
    path = Path(name)
    if (model != "final" or compiled) and not (name not in CONTROLLERS and path.is_dir()):
        # Silently playing the one network a policy file holds would report it as "best".
        given = f"model={model!r}" if model != "final" else "compiled=True"
        raise ValueError(
            f"{given} chooses among a run directory's networks; {name} is not a run "
            "directory (a compiled policy file holds one network)"
        )
    if name in CONTROLLERS:
        return make_named(name, env, contexts, params, seed)
    if not path.exists():
        raise FileNotFoundError(
            f"no controller {name!r}: not a run directory, not a compiled policy file, and "
            f"not one of {', '.join(CONTROLLERS)}"
        )
    refuse_other_kinds(path, (FileKind.RUN_DIR, FileKind.POLICY), controller_sources())
    if identify(path) is FileKind.TORCH_FILE:  # an amortised belief's weights (issue 61)
        from spikectl.agents.amortised_controller import (
            AmortisedController,
            belief_from_state,
            read_state_dict,
        )
        from spikectl.agents.belief_policy import is_belief_policy_state, load_belief_policy

        played_params = _played_on(env, contexts, params).params
        state = read_state_dict(path)
        if is_belief_policy_state(state):  # the belief and a policy trained on it
            return load_belief_policy(path, played_params, state)
        return AmortisedController(belief_from_state(path, state), played_params, seed=seed)
    if path.is_dir():
        network = load_agent(path, model=model)
        if not compiled:
            from spikectl.agents.greedy import GreedyController

            _played_on(env, contexts, params)  # refuses what it cannot play
            return GreedyController(network, per_environment=per_environment)
        from spikectl.agents.compiled import CompiledPolicy
        from spikectl.agents.policy_file import PolicyFileError

        try:
            return CompiledPolicy.from_network(network)
        except (PolicyFileError, ValueError) as error:
            raise PolicyFileError(f"{path} cannot be compiled: {error}") from None
    from spikectl.agents.compiled import CompiledPolicy

    return CompiledPolicy.load(path)


def _played_on(env: Any, contexts: ContextSet | None, params: NeuronParams | None) -> Played:
    """What a controller plays: ``env``'s contexts and extensions where it is given, else
    ``contexts``', else ``params`` alone (with the paper's extensions)."""
    extensions = Extensions()
    if env is not None:
        unwrapped = getattr(env, "unwrapped", env)
        missing = [key for key in ("contexts", "extensions") if not hasattr(unwrapped, key)]
        if missing:
            raise TypeError(
                f"env must be a spikectl NeuronControlEnv or NeuronControlVectorEnv, got "
                f"{type(env).__name__} (it has no {', '.join(missing)})"
            )
        contexts, extensions = unwrapped.contexts, unwrapped.extensions
    elif contexts is not None:
        extensions = contexts.extensions
    if contexts is not None:  # the contexts' own params, as the environment plays them
        if params is not None:
            contexts.check_params(params, "params=", "the controller plays the contexts' own: "
                                  "leave params out")  # fmt: skip
        params = contexts.params
    return Played(contexts, params, extensions)


def make_named(
    name: str, env: Any, contexts: ContextSet | None, params: NeuronParams | None, seed: int
) -> Controller:
    """The registered controller ``name`` made for what ``env`` / ``contexts`` / ``params``
    play (see :func:`load_controller`)."""
    entry = CONTROLLERS.load(name)
    played = _played_on(env, contexts, params)
    if entry.privileged and played.contexts is None:
        raise ValueError(
            f"the {name} controller replays a known answer per context: give env= or contexts="
        )
    return load_target(entry.make)(played, seed)
