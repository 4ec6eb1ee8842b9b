"""The agent's network of an Experiment, whatever learner trains it: built from
``config.train.seed`` without touching Torch's global generator, or started from the
weights ``config.agent.init_from`` names (``spikectl train --init-from``), which are
checked here before a run makes any directory.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import torch

from spikectl.agents import make_agent
from spikectl.config_errors import ConfigError
from spikectl.file_kinds import RECOGNISED, FileKind, identify
from spikectl.training.run_files import BEST_MODEL_FILE, RunDirError
from spikectl.training.torch_files import load_model_weights


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
