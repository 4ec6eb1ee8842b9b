"""K independent networks of one architecture as one batched computation (seed groups).

:class:`StackedNetworks` holds the parameters of K networks stacked along a leading
seed dimension ``[K, ...]`` and runs any of the network's methods on inputs with that
leading dimension through ``torch.func.vmap`` and ``functional_call``: one batched call
serves all K. Seed k's slice of every parameter is exactly the state dict of the plain
network it was stacked from (same names, shapes and layout), so each seed saves and
loads as a plain ``model.pt``.

``nn.LSTM`` has no vmap rule (pytorch/pytorch#105982), so the template the calls run
through has every ``nn.LSTM`` replaced by :class:`StackableLSTM`: nn.LSTM's equations
and parameter names written with ops vmap can batch.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn
from torch.func import functional_call, stack_module_state, vmap
from torch.nn.attention import SDPBackend, sdpa_kernel

LSTM_PARAMETERS = ("weight_ih_l0", "weight_hh_l0", "bias_ih_l0", "bias_hh_l0")


class StackableLSTM(nn.Module):
    """A one-layer, batch-first ``nn.LSTM`` written out step by step so vmap can batch it.

    Same parameters as the ``nn.LSTM`` it copies (``weight_ih_l0`` [4H, F],
    ``weight_hh_l0`` [4H, H], ``bias_ih_l0`` and ``bias_hh_l0`` [4H], gates in nn.LSTM's
    order input, forget, cell, output) and the same call: x [B, T, F] and (h0, c0), each
    [1, B, H] → y [B, T, H] and (h, c), each [1, B, H]. Equal to nn.LSTM up to float
    rounding (CPU nn.LSTM runs a fused oneDNN kernel).
    """

    def __init__(self, lstm: nn.LSTM) -> None:
        super().__init__()
        if (
            lstm.num_layers != 1 or not lstm.batch_first or lstm.bidirectional
            or lstm.proj_size or not lstm.bias
        ):  # fmt: skip
            raise ValueError(
                "StackableLSTM copies one-layer, batch-first, unidirectional nn.LSTMs with "
                f"biases and no projection, got {lstm}"
            )
        self.hidden_size = lstm.hidden_size
        for name in LSTM_PARAMETERS:
            self.register_parameter(name, nn.Parameter(getattr(lstm, name).detach().clone()))

    def forward(
        self, x: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor]
    ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        h, c = state[0][0], state[1][0]  # [B, H] each
        x_gates = F.linear(x, self.weight_ih_l0, self.bias_ih_l0)  # [B, T, 4H]
        outputs = []
        # unbind, not x_gates[:, t]: indexing's backward would zero-fill a [B, T, 4H] tensor
        # for every step.
        for x_gates_t in x_gates.unbind(1):
            gates = x_gates_t + F.linear(h, self.weight_hh_l0, self.bias_hh_l0)  # [B, 4H]
            input_gate, forget_gate, cell_gate, output_gate = gates.chunk(4, dim=-1)  # [B, H]
            c = torch.sigmoid(forget_gate) * c + torch.sigmoid(input_gate) * torch.tanh(cell_gate)
            h = torch.sigmoid(output_gate) * torch.tanh(c)  # [B, H]
            outputs.append(h)
        return torch.stack(outputs, dim=1), (h.unsqueeze(0), c.unsqueeze(0))  # y: [B, T, H]


def stackable_copy(module: nn.Module) -> nn.Module:
    """A deep copy of ``module`` with every ``nn.LSTM`` replaced by a StackableLSTM
    (same parameter names, so the copy loads the original's state dict)."""
    module = copy.deepcopy(module)
    for name, child in list(module.named_modules()):
        if isinstance(child, nn.LSTM):
            parent_name, _, attribute = name.rpartition(".")
            parent = module.get_submodule(parent_name) if parent_name else module
            if parent is module and not parent_name and not attribute:
                raise ValueError("stackable_copy: the module itself is an nn.LSTM")
            setattr(parent, attribute, StackableLSTM(child))
    return module


class _MethodCall(nn.Module):
    """Calls a named method of the wrapped module, so functional_call reaches any method."""

    def __init__(self, module: nn.Module) -> None:
        super().__init__()
        self.module = module

    def forward(self, method: str, *args):
        # CPU's fused attention kernel has no vmap rule (a slow per-seed loop); the math
        # kernel is made of batchable ops.
        with sdpa_kernel(SDPBackend.MATH):
            return getattr(self.module, method)(*args)


class StackedNetworks:
    """The parameters of K networks of one architecture stacked ``[K, ...]``.

    ``params`` maps each parameter name of the plain network to its stacked tensor (a
    leaf; trainable when built with ``trainable=True``). ``call(method, *args)`` runs
    ``network.method`` for every seed in one vmapped call; every tensor argument has the
    seed dimension first.
    """

    def __init__(self, networks: Sequence[nn.Module], trainable: bool = True) -> None:
        if not networks:
            raise ValueError("StackedNetworks needs at least one network")
        kinds = {type(network) for network in networks}
        if len(kinds) != 1:
            raise ValueError(f"StackedNetworks stacks networks of one class, got {kinds}")
        self.template = stackable_copy(networks[0])
        self._caller = _MethodCall(self.template)
        params, buffers = stack_module_state(list(networks))
        if buffers:
            raise ValueError(f"StackedNetworks: buffers are not supported, got {sorted(buffers)}")
        self.params: dict[str, torch.Tensor] = {
            name: tensor.detach().clone().requires_grad_(trainable)
            for name, tensor in params.items()
        }  # each [K, ...]
        self.names = list(networks[0].state_dict())
        if sorted(self.names) != sorted(self.params):
            raise ValueError("StackedNetworks: the state dict holds non-parameter entries")

    @property
    def size(self) -> int:
        """K, the number of stacked networks."""
        return next(iter(self.params.values())).shape[0]

    def parameters(self) -> list[torch.Tensor]:
        return [self.params[name] for name in self.names]

    def __getattr__(self, name: str):
        # Attributes of the architecture (sizes, equivariant, ...) come from the template.
        if name.startswith("_") or name in ("template", "params", "names"):
            raise AttributeError(name)
        return getattr(self.template, name)

    def call(self, method: str, *args, params: dict[str, torch.Tensor] | None = None):
        """``network.method(*args)`` for each seed at once: args with a leading [K]."""
        params = self.params if params is None else params

        def one_seed(seed_params, *seed_args):
            prefixed = {f"module.{name}": value for name, value in seed_params.items()}
            return functional_call(self._caller, prefixed, (method, *seed_args))

        return vmap(one_seed)(params, *args)

    def bound(self, params: dict[str, torch.Tensor]) -> BoundNetwork:
        """The network with one seed's ``params`` (inside a vmapped function)."""
        return BoundNetwork(self._caller, params)

    def state_dict(self, k: int) -> dict[str, torch.Tensor]:
        """Seed k's parameters as the plain network's state dict (copies)."""
        return {name: self.params[name][k].detach().clone() for name in self.names}

    def stacked_state(self) -> dict[str, torch.Tensor]:
        """All K networks' parameters, detached copies ``[K, ...]``."""
        return {name: self.params[name].detach().clone() for name in self.names}

    @torch.no_grad()
    def load_stacked_state(self, state: dict[str, torch.Tensor]) -> None:
        """Restore what :meth:`stacked_state` returned (names and shapes must match)."""
        if sorted(state) != sorted(self.params):
            raise ValueError("the saved stacked networks have other parameters than this one")
        for name, value in state.items():
            if value.shape != self.params[name].shape:
                raise ValueError(
                    f"stacked parameter {name} has shape {tuple(value.shape)}, expected "
                    f"{tuple(self.params[name].shape)}"
                )
            self.params[name].copy_(value)


class BoundNetwork:
    """One seed's view inside a vmapped function: the network's methods with given
    parameters, so that code written for a plain network (the trainer's losses) runs."""

    def __init__(self, caller: _MethodCall, params: dict[str, torch.Tensor]) -> None:
        self._caller = caller
        self._params = {f"module.{name}": value for name, value in params.items()}

    def _call(self, method: str, *args):
        return functional_call(self._caller, self._params, (method, *args))

    def __call__(self, *args):
        return self._call("forward", *args)

    def encode(self, *args):
        return self._call("encode", *args)

    def q_values(self, *args):
        return self._call("q_values", *args)

    def step(self, *args):
        return self._call("step", *args)

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self._caller.module, name)
