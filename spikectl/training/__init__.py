"""Training: the run around any learner, its configuration tree and its presets.

The entry points a user calls (the ``spikectl train`` command calls the same):

- :func:`spikectl.training.run.train` trains one run in a directory and returns its
  metrics rows; :func:`~spikectl.training.run.train_seeds` trains several seeds in one
  process, and :func:`~spikectl.training.run.train_runs` is the one path both take.
- :class:`spikectl.training.config.Experiment` is the configuration of a run (the
  environment, the agent, the run, the learner), a tree of frozen dataclasses that
  ``config.json`` stores; :data:`spikectl.training.presets.PRESETS` holds the named ones
  (``paper``, ``quick``, ``smoke``, ``guided``, ...).
- The learners' configurations: :class:`~spikectl.training.learners.DQNConfig`,
  :class:`~spikectl.training.learners.GuidedConfig` and
  :class:`~spikectl.training.learners.PQNConfig`.
- A trained run read back: :func:`spikectl.training.loaders.load_controller`
  (re-exported as ``spikectl.load_controller``), :func:`~spikectl.training.loaders.load_agent`
  and :func:`spikectl.training.evaluate.evaluate_run`.

Example (a run of the ``smoke`` preset, seconds on one core)::

    from spikectl.training.presets import PRESETS
    from spikectl.training.run import train

    rows = train(PRESETS["smoke"], "runs/smoke")
    print(rows[-1]["test_return"])

This package imports PyTorch, so it is imported by name, not from ``spikectl``.
"""
