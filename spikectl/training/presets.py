"""The presets: instances of the configuration tree (``spikectl.training.config``).

- ``paper``: Table 2 exactly (1 M environment steps, batches of 5 episodes, ...): every
  default of the tree;
- ``quick``: the paper's learner fast, under 15 minutes on one CPU core (the default
  preset, and the base of the Figure 4 and 5 reproductions and the suite's TDRQN rows);
- ``smoke``: seconds, for tests;
- and every learner's own, registered beside its config class
  (``spikectl.training.learners``): ``guided`` (the README's main job), ``pqn``, ...
"""

from __future__ import annotations

from spikectl.agents import AgentSizes
from spikectl.training.config import AgentConfig, EnvConfig, Experiment, TrainConfig
from spikectl.training.learners import DQNConfig, learner_entries

PAPER = Experiment()
"""Table 2 of the paper exactly: every default of the configuration tree (1 M environment
steps, the paper's network sizes, batches of 5 episodes)."""

QUICK = Experiment(
    agent=AgentConfig(
        sizes=AgentSizes(
            lstm_hidden=64,
            attn_width=64,
            attn_ff=128,
            tdrqn_head_hidden=(128, 64),
            ff_hidden=256,
            head_hidden=(256, 128, 64),
            inputs=("target", "target-voltage"),
            do_nothing_head="pooled",
        ),
    ),
    train=TrainConfig(
        total_env_steps=264_000,
        num_envs=16,
        eval_every_episodes=400,
        checkpoint_every_episodes=800,
        torch_threads=1,
    ),
    learner=DQNConfig(
        updates_per_round=32,
        batch_size=8,
        buffer_size=40_000,
        learning_starts=16,
        learning_rate=2e-3,
        learning_rate_end_fraction=0.1,
        gamma=0.9,
        tau=0.05,
        n_step=3,
        aux_voltage_weight=1.0,
        explore_do_nothing=0.75,
    ),
)
"""The paper's learner fast (docs/training.md, "Learning fast"): 4 400 episodes, 8 800
updates of 8 episodes, n-step targets, the auxiliary next-voltage loss, the target's
voltage in each neuron's input, a pooled do-nothing head, do-nothing-biased exploration,
gamma 0.9, lr 2e-3 decaying linearly to 2e-4, half-width networks, one Torch thread.
Older sweep files in docs/results pin the dueling do-nothing head and constant lr the
preset once had (the research record, docs/research/index.md, has the history)."""

SMOKE = Experiment(
    env=EnvConfig(episode_length=20, n_neurons=5, n_train=6, n_test=6, n_val=6),
    agent=AgentConfig(
        sizes=AgentSizes(
            lstm_hidden=16,
            target_embed=4,
            pattern_embed=4,
            ff_hidden=32,
            head_hidden=(32,),
            tdrqn_head_hidden=(32,),
            attn_width=16,
            attn_ff=32,
            value_hidden=(16,),
        ),
    ),
    train=TrainConfig(
        total_env_steps=40 * 20 * 8,
        num_envs=8,
        eval_every_episodes=80,
        checkpoint_every_episodes=80,
        torch_threads=1,
        progress=False,
    ),
    learner=DQNConfig(
        updates_per_round=2,
        batch_size=4,
        buffer_size=200,
        learning_starts=8,
        learning_rate=1e-3,
    ),
)
"""Seconds on one core: 5-neuron networks, 20-step episodes, tiny networks (tests)."""

BASE_PRESETS: dict[str, tuple[Experiment, str]] = {
    "paper": (
        PAPER,
        "Table 2 exactly: 1 M environment steps, the paper's network sizes (days on a CPU).",
    ),
    "quick": (
        QUICK,
        "The paper's learner fast: n-step targets, auxiliary loss, half-width nets (~15 min).",
    ),
    "smoke": (SMOKE, "Seconds: 5-neuron networks, 20-step episodes, tiny networks (for tests)."),
}
"""The presets of the tree itself, each with its line of help; every learner adds its own
(``spikectl.training.learners``, each beside its config class)."""


def _presets() -> dict[str, tuple[Experiment, str]]:
    presets = dict(BASE_PRESETS)
    bases = {name: experiment for name, (experiment, _) in BASE_PRESETS.items()}
    for entry in learner_entries():
        for preset in entry.presets:
            if preset.name in presets:
                raise ValueError(f"the {entry.name} learner's preset {preset.name!r} is taken")
            presets[preset.name] = (preset.build(bases), preset.help)
    return presets


_ALL = _presets()
PRESETS: dict[str, Experiment] = {name: experiment for name, (experiment, _) in _ALL.items()}
"""Every preset by name: the tree's and the learners'."""
PRESET_HELP: dict[str, str] = {name: line for name, (_, line) in _ALL.items()}
"""One line per preset, for ``spikectl train --help`` (read from the same table)."""
