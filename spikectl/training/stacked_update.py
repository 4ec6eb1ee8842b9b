"""The pieces of a stacked update: K seeds' double-Q losses, gradients and Adam steps as
one batched computation over networks stacked along a leading seed dimension
(``spikectl.agents.stacked``, ``torch.func.vmap``).

The training loop trains a group's seeds one after another, each bit-identical to the
seed alone. Stacking computes the same maths for all K at once, which pays where one
update is launch-bound (a GPU) and not on a CPU (0.62-0.86x the throughput of separate
processes here, docs/benchmarks.md); its results differ from the looped seeds' in the
last bits of floating-point rounding. ``benchmarks/bench_ensemble.py`` measures it.
"""

from __future__ import annotations

import torch


def stack_seeds(seed_tensors: list[dict]) -> dict:
    """K seeds' ``batch_tensors`` stacked into one dict of [K, ...] tensors."""
    first = seed_tensors[0]
    return {
        key: stack_seeds([seed[key] for seed in seed_tensors])
        if isinstance(first[key], dict)
        else torch.stack([seed[key] for seed in seed_tensors])
        for key in first
    }


@torch.no_grad()
def clip_grad_norm_per_seed(parameters: list[torch.Tensor], max_norm: float) -> torch.Tensor:
    """``torch.nn.utils.clip_grad_norm_`` for each seed of stacked parameters [K, ...]:
    seed k's gradients are scaled by min(1, max_norm / (‖g_k‖ + 1e-6)), where ‖g_k‖ is
    the 2-norm over all of seed k's gradients. Returns the norms [K]."""
    grads = [p.grad for p in parameters if p.grad is not None]
    K = grads[0].shape[0]
    norms = torch.stack(
        [torch.linalg.vector_norm(g.reshape(K, -1), 2, dim=1) for g in grads]
    )  # [P, K]
    total = torch.linalg.vector_norm(norms, 2, dim=0)  # [K]
    scale = torch.clamp(max_norm / (total + 1e-6), max=1.0)  # [K]
    for g in grads:
        g.mul_(scale.reshape(K, *([1] * (g.dim() - 1))))
    return total
