"""What counts as a spike in the networks' input: one level, shared by the PyTorch
features (``spikectl.agents.features``) and the compiled forward
(``spikectl.agents.policy_kernel``). It imports nothing, so that the compiled policy
reads it without PyTorch."""

VISIBLE_SPIKE_LEVEL = 1.0 - 1e-4
"""A normalised potential (V - V_r) / (V_th - V_r) at or above this is a visible spike
(V >= V_th, docs/model.md, with room for float32 rounding: 1e-4 of V_th - V_r is 2 µV at
the defaults)."""
