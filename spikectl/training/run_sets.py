"""The context sets of a run (training, test and validation), kept in its run directory,
and the environments that play them with the run's model and extensions."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from spikectl.contexts import ContextSet, make_splits
from spikectl.contexts.splits import make_validation_set
from spikectl.envs.rollout import EpisodeBatch, evaluate_policy
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.seeds import EVAL_STREAM, environment_seed
from spikectl.training.config import Experiment

TRAIN_FILE = "train_contexts.npz"
TEST_FILE = "test_contexts.npz"
VAL_FILE = "val_contexts.npz"


def generated_contexts(config: Experiment) -> tuple[ContextSet, ContextSet]:
    """The (train, test) sets the config's sizes, ``context_seed``, params and
    context-level extensions generate."""
    env = config.env
    return make_splits(
        env.n_train, env.n_test, env.n_neurons, env.episode_length, env.context_seed,
        params=env.params, extensions=env.extensions,
    )  # fmt: skip


def recorded_config(config: Experiment, run_dir: Path, resume: bool) -> Experiment:
    """The config as the run records it: where a context file is given, ``n_train`` /
    ``n_test`` are its size, not the preset's (reports group runs by ``n_train``). A
    resumed run keeps the sizes its config.json holds (runs of spikectl before this
    recorded the preset's); a damaged file is refused here, before config.json is written."""
    from spikectl.training.run_files import CONFIG_FILE, read_config

    env = config.env
    if env.train_contexts is None and env.test_contexts is None:
        return config
    if resume and (run_dir / CONFIG_FILE).exists():
        saved = read_config(run_dir).env
        sizes = {"n_train": saved.n_train, "n_test": saved.n_test}
    else:
        sizes = {
            name: len(ContextSet.load(path))
            for name, path in (("n_train", env.train_contexts), ("n_test", env.test_contexts))
            if path is not None
        }
    return dataclasses.replace(config, env=dataclasses.replace(env, **sizes))


def load_or_make_contexts(
    config: Experiment, run_dir: Path
) -> tuple[ContextSet, ContextSet, ContextSet | None]:
    """The run's (train, test, validation) sets: from the run directory when it has them
    (a resumed run), else from the config's files or generated, then saved into the run
    directory. The validation set (None when ``n_val`` is 0) is generated to share no
    topology with the training and test sets actually used."""
    env = config.env
    paths = [run_dir / TRAIN_FILE, run_dir / TEST_FILE]
    if env.n_val:
        paths.append(run_dir / VAL_FILE)
    if all(path.exists() for path in paths):
        train, test = ContextSet.load(paths[0]), ContextSet.load(paths[1])
        validation = ContextSet.load(paths[2]) if env.n_val else None
    else:
        train = ContextSet.load(env.train_contexts) if env.train_contexts is not None else None
        test = ContextSet.load(env.test_contexts) if env.test_contexts is not None else None
        for name, contexts, path, size in (
            ("training", train, env.train_contexts, env.n_train),
            ("test", test, env.test_contexts, env.n_test),
        ):
            if contexts is not None:
                check_model(contexts, config, name)
                if len(contexts) != size:
                    raise ValueError(
                        f"{path} holds {len(contexts)} {name} contexts, the run records "
                        f"{size} (n_{name.removesuffix('ing')}): was the file changed? Start "
                        "the run again in a new --run-dir"
                    )
        if train is None or test is None:
            generated = generated_contexts(config)
            train = generated[0] if train is None else train
            test = generated[1] if test is None else test
        validation = None
        if env.n_val:
            validation = make_validation_set(
                env.n_val, (train, test), env.n_neurons, env.episode_length, env.context_seed,
                params=env.params, extensions=env.extensions,
            )  # fmt: skip
        for path, contexts in zip(paths, (train, test, validation), strict=False):
            contexts.save(path)
    sets = {"training": train, "test": test, "validation": validation}
    for name, contexts in sets.items():
        if contexts is not None and (contexts.n_neurons, contexts.episode_length) != (
            env.n_neurons,
            env.episode_length,
        ):
            raise ValueError(
                f"the {name} contexts have {contexts.n_neurons} neurons and episodes of "
                f"{contexts.episode_length} steps; the config says {env.n_neurons} and "
                f"{env.episode_length}"
            )
        if contexts is not None:
            check_model(contexts, config, name)
    for first, second in (("training", "test"), ("training", "validation"), ("test", "validation")):
        if sets[first] is None or sets[second] is None:
            continue
        shared = sets[first].duplicate_topologies(sets[second])
        if shared:
            raise ValueError(
                f"{len(shared)} {second} context(s) share a topology with the {first} set "
                f"(first: {first} {shared[0][0]}, {second} {shared[0][1]}): the sets must be "
                "disjoint"
            )
    return train, test, validation


def check_model(contexts: ContextSet, config: Experiment, name: str) -> None:
    """Refuse a context set made with other NeuronParams or context-level extensions than
    the config's: the agent normalises its input with the config's params, and the
    environment plays the contexts' own."""
    env = config.env
    contexts.check_params(
        env.params, "the config's (--params.*)", "give theirs with the --params.* flags named",
        f"the {name} contexts",
    )  # fmt: skip
    if contexts.extensions != env.extensions.context_part():
        raise ValueError(
            f"extensions: the {name} contexts were made with context-level extensions "
            f"{contexts.extensions.to_dict(only_changed=True)}, the config says "
            f"{env.extensions.context_part().to_dict(only_changed=True)} (--extensions.*)"
        )


def check_trained_params(contexts: ContextSet, config: Experiment, run: str, name: str) -> None:
    """Refuse contexts (``name``) made with other NeuronParams than those a trained
    ``run`` (its config) was trained on: its agent normalises its input with those."""
    contexts.check_params(
        config.env.params, f"the params {run} was trained on (its config.json)",
        "its agent would play another model: play it on contexts made with its params", name,
    )  # fmt: skip


def make_env(config: Experiment, contexts: ContextSet, num_envs: int) -> NeuronControlVectorEnv:
    """A vector environment on ``contexts`` (which carry the neuron parameters they were
    made with: the environment plays those) with the config's environment extensions."""
    return NeuronControlVectorEnv(
        num_envs, contexts=contexts, extensions=config.env.extensions.environment_part()
    )


def stream_seed(config: Experiment, stream: int, *more: int) -> int:
    """A seed for an environment's own draws, derived from the training seed."""
    return environment_seed(config.train.seed, stream, *more)


def baseline_episodes(config: Experiment, contexts: ContextSet, policy) -> EpisodeBatch:
    """A reference policy's episodes on a set, in the run's environment (the set's
    params, the run's extensions and evaluation seed)."""
    return evaluate_policy(
        contexts, policy, extensions=config.env.extensions.environment_part(),
        seed=stream_seed(config, EVAL_STREAM),
    )  # fmt: skip
