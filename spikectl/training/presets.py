"""The presets: instances of the configuration tree (``spikectl.training.config``).

- ``paper``: Table 2 exactly (1 M environment steps, batches of 5 episodes, ...): every
  default of the tree;
- ``quick``: the paper's learner fast, under 15 minutes on one CPU core (the default
  preset, and the base of the Figure 4 and 5 reproductions and the suite's TDRQN rows);
- ``guided``: the README's main job, quick with a teacher; ``pqn``: quick's run with
  parallel Q-learning without replay;
- ``smoke``: seconds, for tests.
"""

from __future__ import annotations

import dataclasses

from spikectl.agents import AgentSizes
from spikectl.training.config import AgentConfig, EnvConfig, Experiment, TrainConfig
from spikectl.training.learners import DQNConfig, GuidedConfig, PQNConfig

PAPER = Experiment()

QUICK = Experiment(
    agent=AgentConfig(
        sizes=AgentSizes(
            lstm_hidden=64,
            attn_width=64,
            attn_ff=128,
            tdrqn_head_hidden=(128, 64),
            ff_hidden=256,
            head_hidden=(256, 128, 64),
            target_voltage_in_input=True,
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
"""The paper's learner fast (the README's main job until 2026-11-24): ~14 minutes on one
core of the project's 2-core machine (docs/training.md, "Learning fast"): 4 400
episodes, 8 800 updates of 8 episodes, n-step targets, the auxiliary next-voltage
loss, the target's voltage in each neuron's input, a pooled do-nothing head,
do-nothing-biased exploration, gamma 0.9, lr 2e-3 decaying linearly to 2e-4,
half-width networks, one Torch thread. Until 2026-11-23 the preset had the dueling
do-nothing head and a constant lr (docs/results sweep files made with it pin both)."""

GUIDED = dataclasses.replace(
    QUICK,
    env=dataclasses.replace(QUICK.env, n_train=1000),
    learner=GuidedConfig(
        **{**dataclasses.asdict(QUICK.learner), "updates_per_round": 24},
        teacher="identify",
        imitation_weight_end=0.2,
        connectivity_weight=0.1,
    ),
)
"""The README's main job: the quick preset's run and sizes with the teacher-guided learner
(docs/training.md, "Teacher-guided learning"): identify-and-plan labels the states the
agent visits; the imitation weight falls from 1 to a floor of 0.2 over the first half of
the episodes and stays there (chosen on the validation networks, 2026-11-24: 0.816 ±
0.006 against 0.773 ± 0.002 weaned to 0), and a privileged auxiliary loss of weight 0.1
asks the features for each neuron's synapse onto the target (validation 0.824 ± 0.005
against 0.816 ± 0.006 without). 24 updates a round, not the quick preset's 32 (6 600
updates in all; 2026-11-24, fourth stop): the same unseen return (0.811 ± 0.003) for
0.75 of the core-minutes, measured side by side (docs/training.md). 1 000 training
networks, not 100 (2026-11-25, second session; chosen on validation: 0.834 ± 0.001
against 0.817 ± 0.009 on 100, 3 seeds each on one host): the same 4 400 episodes see
each network about 4 times instead of 44, and the learner no longer scores higher on
its training networks than on unseen ones. The test and validation sets are the same
100 networks either way (``make_splits``)."""

PQN = dataclasses.replace(
    QUICK,
    agent=dataclasses.replace(
        QUICK.agent, sizes=dataclasses.replace(QUICK.agent.sizes, layer_norm=True)
    ),
    train=dataclasses.replace(QUICK.train, num_envs=32),
    learner=PQNConfig(
        epochs=16,
        minibatch_size=8,
        q_lambda=0.65,
        learning_rate=1e-3,
        learning_rate_end_fraction=0.1,
        gamma=0.9,
        aux_voltage_weight=1.0,
        explore_do_nothing=0.75,
    ),
)
"""The quick preset's environment, network (plus LayerNorm) and environment steps with
parallel Q-learning without replay (docs/training.md, "Parallel Q-learning without
replay"): 32 episodes a round (137 rounds, 4 384 episodes), 16 epochs of minibatches of
8 episodes over each round (8 768 updates of 8 episodes, as quick's 8 800), Q(0.65)
returns, the auxiliary loss and exploration of quick, lr 1e-3 decaying to 1e-4."""

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

PRESETS: dict[str, Experiment] = {
    "paper": PAPER,
    "quick": QUICK,
    "guided": GUIDED,
    "pqn": PQN,
    "smoke": SMOKE,
}
PRESET_HELP: dict[str, str] = {
    "paper": "Table 2 exactly: 1 M environment steps, the paper's network sizes (days on a CPU).",
    "quick": "The paper's learner fast: n-step targets, auxiliary loss, half-width nets (~15 min).",
    "guided": "The main job: quick on 1 000 networks, taught by identify-and-plan (floor 0.2).",
    "pqn": "The quick run with PQN: Q(lambda) on parallel episodes, no replay, LayerNorm.",
    "smoke": "Seconds: 5-neuron networks, 20-step episodes, tiny networks (for tests).",
}
"""One line per preset, for ``spikectl train --help``."""
