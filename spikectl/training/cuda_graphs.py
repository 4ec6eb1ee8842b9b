"""CUDA graphs for a stacked seed group (``train.cuda_graphs``, on by default on a GPU).

On a GPU a stacked update is bound by kernel launches, not arithmetic: the written-out
LSTM (``spikectl.agents.stacked``) is about 60 small steps forward and backward, each a
few kernels, so a group of one took 79 ms an update where the cuDNN network takes 13 ms
(docs/benchmarks.md). A CUDA graph records the kernels of one call once and replays them
all with one launch. What that asks of the call:

- fixed shapes and devices: its inputs are copied into tensors allocated once (the
  "static" inputs) before each replay, and its outputs are the graph's own tensors,
  overwritten by the next replay;
- no host synchronisation inside (no ``.item()``, no data-dependent shapes);
- an optimizer whose step runs on the device: Adam with ``capturable=True`` and its
  learning rate in a device tensor, so a schedule changes it in place
  (:func:`make_capturable`).

The replayed kernels are the eager call's, with the same inputs, so a captured update
computes what the eager one does; the capturable Adam forms its bias correction on the
device, which may differ from the eager one's in the last bit.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from torch.utils._pytree import tree_flatten, tree_map

WARMUP_CALLS = 3
"""Eager calls on a side stream before the capture (what PyTorch's docs ask: they set up
cuBLAS handles and lazily allocated state such as Adam's moments)."""


class CapturedCall:
    """``function(*inputs)`` recorded in a CUDA graph, replayed on new inputs of the same
    shapes, dtypes and device.

    ``inputs`` are example inputs (any nesting of tuples, lists and dicts of tensors): they
    are cloned into the static inputs. The function runs ``WARMUP_CALLS`` times on a side
    stream before the capture; ``snapshot``, when given, is called before the warm-up and
    returns a function that undoes what the warm-up changed (an update's parameters and
    optimizer state), so that the first replay is the first update.
    """

    def __init__(
        self,
        function: Callable[..., Any],
        inputs: tuple,
        snapshot: Callable[[], Callable[[], None]] | None = None,
    ) -> None:
        self.static_inputs = tree_map(lambda tensor: tensor.detach().clone(), inputs)
        self._leaves, self._spec = tree_flatten(self.static_inputs)
        undo = snapshot() if snapshot is not None else None
        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side):
            for _ in range(WARMUP_CALLS):
                function(*self.static_inputs)
        torch.cuda.current_stream().wait_stream(side)
        if undo is not None:
            undo()
        self.graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(self.graph):
            self.static_outputs = function(*self.static_inputs)

    def __call__(self, *inputs) -> Any:
        """Copy ``inputs`` into the static inputs, replay, return the static outputs."""
        leaves, spec = tree_flatten(inputs)
        if spec != self._spec:
            raise ValueError(f"a captured call takes inputs shaped like {self._spec}, got {spec}")
        for static, value in zip(self._leaves, leaves, strict=True):
            if static.shape != value.shape or static.dtype != value.dtype:
                raise ValueError(
                    f"a captured call's input is {tuple(static.shape)} {static.dtype}, got "
                    f"{tuple(value.shape)} {value.dtype} (a CUDA graph has fixed shapes)"
                )
            static.copy_(value)
        self.graph.replay()
        return self.static_outputs


def make_capturable(optimizer: torch.optim.Optimizer, device: torch.device | str) -> None:
    """Let ``optimizer`` (Adam) run inside a CUDA graph: its step counts on the device and
    its learning rate a device tensor that the learner's ``set_learning_rate`` fills in place.
    Idempotent; the moments are kept."""
    for group in optimizer.param_groups:
        group["capturable"] = True
        if not isinstance(group["lr"], torch.Tensor):
            group["lr"] = torch.tensor(float(group["lr"]), device=device)
    for state in optimizer.state.values():
        if "step" in state:
            state["step"] = state["step"].to(device=device, dtype=torch.float32)


def eager_optimizer_state(optimizer: torch.optim.Optimizer) -> dict[str, Any]:
    """``optimizer.state_dict()`` as an optimizer that was never made capturable saves it
    (a float learning rate, step counts on the CPU), so a checkpoint reads the same
    whether or not the run used CUDA graphs, and resumes on either path."""
    saved = optimizer.state_dict()
    groups = [
        {**group, "lr": float(group["lr"]), "capturable": False}
        for group in saved["param_groups"]
    ]
    state = {
        index: {
            key: value.detach().to("cpu", torch.float32) if key == "step" else value
            for key, value in entry.items()
        }
        for index, entry in saved["state"].items()
    }
    return {"state": state, "param_groups": groups}


def update_snapshot(
    tensors: list[torch.Tensor], optimizer: torch.optim.Optimizer
) -> Callable[[], None]:
    """Save ``tensors`` (parameters the update changes) and the optimizer's state; the
    returned function puts them back in place. A parameter that had no optimizer state
    when saved gets its new state zeroed, which is Adam's state before its first step."""
    with torch.no_grad():
        saved = [tensor.detach().clone() for tensor in tensors]
        saved_state = {
            parameter: {key: value.clone() for key, value in state.items()}
            for parameter, state in optimizer.state.items()
        }

    @torch.no_grad()
    def restore() -> None:
        for tensor, value in zip(tensors, saved, strict=True):
            tensor.copy_(value)
        for parameter, state in optimizer.state.items():
            before = saved_state.get(parameter)
            for key, value in state.items():
                if before is None:
                    value.zero_()
                else:
                    value.copy_(before[key])

    return restore
