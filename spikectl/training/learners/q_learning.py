"""The pieces every Q-learner of the loop shares (the double-Q learner's, the guided
learner's and PQN's): epsilon-greedy collection on the online network, the networks
built from an Experiment without touching Torch's global generator, the learning-rate
setter a CUDA graph can read, one gradient step, and the metrics row of running loss sums.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import torch

from spikectl.agents import make_agent, make_voltage_predictor
from spikectl.agents.greedy import GreedyController
from spikectl.config_errors import ConfigError
from spikectl.envs.env_support import random_legal_actions
from spikectl.file_kinds import RECOGNISED, FileKind, identify
from spikectl.seeds import AUX_HEAD_STREAM, torch_seed
from spikectl.training.learners.protocol import LossDiverged
from spikectl.training.run_files import BEST_MODEL_FILE, RunDirError
from spikectl.training.torch_files import load_model_weights


class EpsilonGreedyPolicy(GreedyController):
    """Acts with the online network's step forward, carrying one hidden state per episode.

    With probability epsilon (per step and episode) a random legal action replaces the
    greedy one: uniform over the legal actions (``explore_do_nothing=None``, the paper),
    or "do nothing" with probability ``explore_do_nothing`` and otherwise a uniform legal
    stimulation. A new instance starts every batch of episodes.
    """

    def __init__(
        self,
        network: torch.nn.Module,
        epsilon: float,
        rng: np.random.Generator,
        device: str,
        explore_do_nothing: float | None = None,
    ) -> None:
        super().__init__(network, device)
        self.epsilon, self.rng, self.explore_do_nothing = epsilon, rng, explore_do_nothing

    def __call__(self, observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        greedy = super().__call__(observations, action_mask)  # [S]
        if self.epsilon <= 0:
            return greedy
        return explore(greedy, action_mask, self.epsilon, self.rng, self.explore_do_nothing)


def explore(
    greedy: np.ndarray,
    action_mask: np.ndarray,
    epsilon: float,
    rng: np.random.Generator,
    explore_do_nothing: float | None,
) -> np.ndarray:
    """Epsilon-greedy: greedy actions [S] with each replaced, with probability epsilon, by
    a random legal one (the draws every policy of a run makes, in this order)."""
    exploring = rng.random(greedy.shape[0]) < epsilon  # [S]
    if explore_do_nothing is None:
        random_actions = random_legal_actions(action_mask, rng)
    else:
        # A random stimulation, replaced by do nothing with probability explore_do_nothing.
        stimulations = action_mask.copy()
        stimulations[:, 0] = False
        random_actions = random_legal_actions(stimulations, rng)
        nothing = rng.random(greedy.shape[0]) < explore_do_nothing
        random_actions[nothing] = -1
    return np.where(exploring, random_actions, greedy)


def build_network(config) -> torch.nn.Module:
    """The online network of an Experiment, initialised from ``config.train.seed``
    without touching Torch's global generator, or from the weights
    ``config.agent.init_from`` names."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.train.seed)
        online = make_agent(
            config.agent.arch, config.env.n_observed, config.env.episode_length,
            config.agent.sizes, params=config.env.params,
        )  # fmt: skip
    if config.agent.init_from is not None:
        load_initial_weights(online, Path(config.agent.init_from), config)
    return online.to(config.train.device)


def check_initial_weights(config) -> None:
    """Refuse (ConfigError) ``config.agent.init_from`` when it names no weights, or
    weights that do not fit the network ``config`` describes (built on the CPU)."""
    if config.agent.init_from is not None:
        build_network(
            dataclasses.replace(config, train=dataclasses.replace(config.train, device="cpu"))
        )


INIT_FROM_TAKES = "it takes a run directory (its best_model.pt), or a model.pt or best_model.pt"


def load_initial_weights(network: torch.nn.Module, path: Path, config: Any = None) -> None:
    """Load into ``network`` the weights ``path`` names: a run directory's best_model.pt,
    or a model.pt or best_model.pt. Any other kind of file (a checkpoint.pt too: its run
    directory holds the network to start from), or weights of another architecture, sizes
    or episode length (or number of neurons, for the fixed-size architectures) than
    ``config``'s, is one ConfigError naming what differs and both values."""
    kind = identify(path)
    if kind is FileKind.MISSING:
        raise ConfigError(("agent", "init_from"), f"names no weights: {path} does not exist")
    if kind is FileKind.RUN_DIR:
        source_config = _source_config(path)
        path = path / BEST_MODEL_FILE
        if not path.exists():
            raise ConfigError(
                ("agent", "init_from"),
                f"names no weights: {path} does not exist (a run without a validation set "
                "keeps no best network): give its model.pt",
            )
    elif kind in (FileKind.MODEL, FileKind.BEST_MODEL):
        source_config = _source_config(path.parent)
    elif kind is FileKind.CHECKPOINT:
        raise ConfigError(
            ("agent", "init_from"),
            f"names {kind.value}, {path}, which holds a learner's whole state: "
            f"{INIT_FROM_TAKES} (give its run directory, {path.parent})",
        )
    elif kind in RECOGNISED or kind in (FileKind.FOLDER, FileKind.NPZ_FILE):
        raise ConfigError(("agent", "init_from"), f"names {kind.value}, {path}: {INIT_FROM_TAKES}")
    else:  # not a spikectl file, or a damaged one: the reader says which
        try:
            load_model_weights(path)
        except RunDirError as error:
            raise ConfigError(("agent", "init_from"), f"{error}: {INIT_FROM_TAKES}") from None
        source_config = None
    if config is not None and source_config is not None:
        fixed_n = not getattr(network, "equivariant", True)
        differences = _network_differences(source_config, config, fixed_n)
        if differences:
            raise ConfigError(
                ("agent", "init_from"),
                f"names weights that do not fit this network: {path} holds a network of "
                f"{'; '.join(differences)}",
            )
    weights = load_model_weights(path)
    try:
        network.load_state_dict(weights)
    except RuntimeError as error:
        raise ConfigError(
            ("agent", "init_from"),
            f"names weights that do not fit this network: {path} "
            f"({_shape_difference(network, weights) or str(error).splitlines()[0].rstrip(':.')}"
            ": another architecture, sizes or episode length, or a fixed-size architecture "
            "trained at another number of neurons)",
        ) from None


def _source_config(run_dir: Path) -> Any:
    """The config of the run that wrote the weights in ``run_dir``, or None when that
    folder holds no readable run config (weights copied out of their run)."""
    from spikectl.training.run_files import CONFIG_FILE, read_config

    if not (run_dir / CONFIG_FILE).is_file():
        return None
    try:
        return read_config(run_dir)
    except RunDirError:
        return None


def _network_differences(source: Any, config: Any, fixed_n: bool) -> list[str]:
    """What shapes the network and differs between the source run's config and this
    one's: 'SETTING SOURCE (this run: VALUE)' each; the number of neurons only where the
    network is of a fixed size (``fixed_n``: per-neuron weights play at any n)."""
    found = []
    pairs = [("arch", source.agent.arch, config.agent.arch),
             ("episode length", source.env.episode_length, config.env.episode_length)]  # fmt: skip
    if fixed_n:
        pairs.append(("n_neurons", source.env.n_observed, config.env.n_observed))
    theirs, ours = dataclasses.asdict(source.agent.sizes), dataclasses.asdict(config.agent.sizes)
    pairs += [(f"sizes.{name}", theirs[name], ours[name]) for name in ours if name in theirs]
    for name, source_value, value in pairs:
        if source_value != value:
            found.append(f"{name} {_plain(source_value)} (this run: {_plain(value)})")
    return found


def _plain(value: Any) -> str:
    return str(list(value)) if isinstance(value, (list, tuple)) else str(value)


def _shape_difference(network: torch.nn.Module, weights: dict[str, torch.Tensor]) -> str:
    """The episode length the pattern code's weights were made for, where it differs (a
    weights file copied out of its run, with no config beside it to compare)."""
    name = "context.pattern.0.weight"
    own = network.state_dict().get(name)
    given = weights.get(name)
    if own is None or given is None or own.ndim != 2 or given.ndim != 2:
        return ""
    if own.shape[1] != given.shape[1]:
        return (
            f"its pattern code reads an episode length of {given.shape[1]} steps (this run: "
            f"{own.shape[1]})"
        )
    return ""


def build_networks(config) -> tuple[torch.nn.Module, torch.nn.Module]:
    """Online and target networks of an Experiment (:func:`build_network` and a copy)."""
    online = build_network(config)
    target = copy.deepcopy(online)
    target.requires_grad_(False)
    return online, target


def build_predictor(config, online: torch.nn.Module) -> torch.nn.Module | None:
    """The auxiliary next-voltage head when ``aux_voltage_weight > 0``, seeded from
    ``config.train.seed`` on a stream of its own (the Q-network's initialisation is unchanged)."""
    if config.learner.aux_voltage_weight <= 0:
        return None
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(torch_seed(config.train.seed, AUX_HEAD_STREAM))
        predictor = make_voltage_predictor(online)
    return predictor.to(config.train.device)


def set_learning_rate(optimizer: torch.optim.Optimizer, learning_rate: float) -> None:
    """Set every parameter group's learning rate, in place where it is a device tensor
    that a CUDA graph reads (``spikectl.training.cuda_graphs``). The schedule is a pure
    function of the episode count, so a resumed run needs no scheduler state."""
    for group in optimizer.param_groups:
        if isinstance(group["lr"], torch.Tensor):
            group["lr"].fill_(learning_rate)
        else:
            group["lr"] = learning_rate


class QLearner:
    """What every Q-learner of the loop does alike, given ``settings`` (a
    :class:`~spikectl.training.learners.q_settings.QSettings`), ``total_episodes``,
    ``network``, ``rng``, ``device``, ``predictor`` and running loss sums: collect
    epsilon-greedily on the online network, drawing from the run's generator, and report
    the metrics row (``updates``, ``epsilon`` and the mean losses since the last row)."""

    settings: Any
    total_episodes: int
    network: torch.nn.Module
    predictor: torch.nn.Module | None
    rng: np.random.Generator
    device: str
    updates: int
    loss_sum: float
    aux_loss_sum: float
    loss_count: int

    def epsilon(self, episode: int) -> float:
        return self.settings.epsilon(episode, self.total_episodes)

    def collection_policy(self, episode: int) -> EpsilonGreedyPolicy:
        return EpsilonGreedyPolicy(
            self.network, self.epsilon(episode), self.rng, self.device,
            self.settings.explore_do_nothing,
        )  # fmt: skip

    def row_metrics(self, episode: int) -> dict[str, float]:
        """The means since the last row (NaN without updates); the sums start again."""
        n = self.loss_count
        row = {
            "updates": self.updates,
            "epsilon": self.epsilon(episode),
            "loss": self.loss_sum / n if n else math.nan,
            "aux_loss": self.aux_loss_sum / n if n and self.predictor is not None else math.nan,
        }
        self.loss_sum, self.aux_loss_sum, self.loss_count = 0.0, 0.0, 0
        return row

    def progress(self, episode: int) -> dict[str, str]:
        return {"eps": f"{self.epsilon(episode):.2f}"}


def gradient_step(learner: Any, loss: torch.Tensor) -> None:
    """One Adam step on ``loss`` over ``learner.trained`` (clipped to the settings'
    ``max_grad_norm`` when it is > 0), counted in ``learner.updates``; a NaN or infinite
    loss stops the run first (:class:`LossDiverged`)."""
    if not torch.isfinite(loss):
        raise LossDiverged(loss.item(), learner.updates + 1)
    learner.optimizer.zero_grad(set_to_none=True)
    loss.backward()
    if learner.settings.max_grad_norm > 0:
        torch.nn.utils.clip_grad_norm_(learner.trained, learner.settings.max_grad_norm)
    learner.optimizer.step()
    learner.updates += 1
    learner.loss_count += 1
