"""Bridges to other simulators: spikectl's controllers acting on networks simulated elsewhere.

Each bridge is a module of its own that needs an extra and is imported only with it;
without the extra, importing it raises :class:`spikectl.config_errors.MissingExtraError`
in one line that says how to install it. This package itself imports nothing.

- :mod:`spikectl.bridges.cleo` (``pip install -c constraints-cleo.txt "spikectl[cleo]"``):
  the network of a context in Brian 2, driven in closed loop by any controller through
  Cleo's ``CLSimulator`` (docs/cleo.md).
"""
