"""Experiments: figures drawn from saved results (and, later, sweeps and statistics)."""
