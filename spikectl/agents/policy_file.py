"""The file of a compiled policy (``spikectl.agents.compiled``): its header, its checks,
and the export of a PyTorch TDRQN or DDRQN to it.

One ``.npz``: a JSON header under ``metadata`` (format name and version, the
architecture, the sizes and options the forward needs, :class:`PolicySpec`) and every
weight as a float32 array under its state-dict name. Reading it needs NumPy only;
:func:`export_policy` imports PyTorch inside, since it reads a PyTorch network.
"""

from __future__ import annotations

import hashlib
import io
import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spikectl.files import atomic_write_bytes

FORMAT_NAME = "spikectl.CompiledPolicy"
FORMAT_VERSION = 2
"""Version 2 adds ``checksum`` to the header (SHA-256 over the header's values and every
weight). Version-1 files carry none, so a changed header over the same weights could not
be told from the exported one: they are refused, naming how to export again."""
SUPPORTED_ARCHITECTURES = ("tdrqn", "ddrqn")
"""What :func:`export_policy` compiles: the per-neuron networks (any n). DRQN and DMDRQN,
fixed-n system networks, are not supported."""
COMPILED_INPUTS = (
    ("target", "target_in_input"),
    ("target-voltage", "target_voltage_in_input"),
    ("others-spiking", "others_spiking_in_input"),
    ("proximity", "proximity_in_input"),
)
"""The input features (``AgentSizes.inputs``) the compiled forward computes, in the only
order it computes them, each with the header field that says whether the file's
network reads it."""
HEADER_KEY = "metadata"
MAX_WIDTH = 4096
"""The widest layer and the most layers a header may declare (far above any preset)."""
MAX_POTENTIAL_MV = 1000.0
"""The largest |V_rest| and |V_threshold| a header may declare, in mV."""


class PolicyFileError(ValueError):
    """A compiled-policy file that is unreadable, foreign, of another version, or whose
    weights do not match its header (the message names the file and the problem)."""


@dataclass(frozen=True)
class PolicySpec:
    """What the compiled forward needs besides the weights: the file's header."""

    architecture: str
    """``tdrqn`` or ``ddrqn``."""
    n_neurons: int
    """The n the network was built for (it runs on any n)."""
    episode_length: int
    """N, the pattern length."""
    v_rest_mV: float
    v_threshold_mV: float
    """The potentials that normalise the voltage input: (V - V_r) / (V_th - V_r)."""
    lstm_hidden: int
    target_embed: int
    pattern_embed: int
    mix_hidden: int
    """DDRQN's per-neuron FF width (``ff_hidden``); unused by TDRQN."""
    attn_width: int
    attn_layers: int
    attn_heads: int
    attn_ff: int
    """TDRQN's transformer; unused by DDRQN."""
    layer_norm_eps: float
    head_hidden: tuple[int, ...]
    """The per-neuron Q head's hidden widths (``tdrqn_head_hidden`` or ``head_hidden``)."""
    value_hidden: tuple[int, ...]
    do_nothing_head: str
    target_in_input: bool
    target_voltage_in_input: bool
    """Whether the network reads each of :data:`COMPILED_INPUTS`: the header's words for
    ``AgentSizes.inputs`` (:attr:`inputs`)."""
    # Fields added after format version 1 have a default: files written before them read
    # as that default.
    others_spiking_in_input: bool = False
    proximity_in_input: bool = False

    @property
    def inputs(self) -> tuple[str, ...]:
        """The network's ``AgentSizes.inputs``: the features of :data:`COMPILED_INPUTS`
        its header switches on."""
        return tuple(name for name, flag in COMPILED_INPUTS if getattr(self, flag))

    @property
    def input_features(self) -> int:
        """F: [v_norm, stimulated, then one column per feature of :attr:`inputs`]."""
        return 2 + len(self.inputs)

    @property
    def mix_width(self) -> int:
        """M: the width of each neuron's embedding after the mixing block."""
        return self.attn_width if self.architecture == "tdrqn" else self.mix_hidden

    def weight_shapes(self) -> dict[str, tuple[int, ...]]:
        """Every weight's state-dict name → shape, as the PyTorch network holds them."""
        F, H, W = self.input_features, self.lstm_hidden, self.attn_width
        shapes: dict[str, tuple[int, ...]] = {
            "lstm.lstm.weight_ih_l0": (4 * H, F),
            "lstm.lstm.weight_hh_l0": (4 * H, H),
            "lstm.lstm.bias_ih_l0": (4 * H,),
            "lstm.lstm.bias_hh_l0": (4 * H,),
        }
        if self.architecture == "tdrqn":
            if H != W:
                shapes |= {"mixer.project.weight": (W, H), "mixer.project.bias": (W,)}
            for layer in range(self.attn_layers):
                prefix = f"mixer.encoder.layers.{layer}."
                for name, shape in (
                    ("self_attn.in_proj_weight", (3 * W, W)),
                    ("self_attn.in_proj_bias", (3 * W,)),
                    ("self_attn.out_proj.weight", (W, W)),
                    ("self_attn.out_proj.bias", (W,)),
                    ("linear1.weight", (self.attn_ff, W)),
                    ("linear1.bias", (self.attn_ff,)),
                    ("linear2.weight", (W, self.attn_ff)),
                    ("linear2.bias", (W,)),
                    ("norm1.weight", (W,)),
                    ("norm1.bias", (W,)),
                    ("norm2.weight", (W,)),
                    ("norm2.bias", (W,)),
                ):
                    shapes[prefix + name] = shape
        else:
            shapes |= {"ff.0.weight": (self.mix_hidden, H), "ff.0.bias": (self.mix_hidden,)}
        E, P, N = self.target_embed, self.pattern_embed, self.episode_length
        shapes |= {
            "context.target.0.weight": (E, 1),
            "context.target.0.bias": (E,),
            "context.pattern.0.weight": (P, N),
            "context.pattern.0.bias": (P,),
        }
        U = self.mix_width + E + P
        for name, width, hidden in (("advantage", U, self.head_hidden),
                                    ("value", 2 * U, self.value_hidden)):  # fmt: skip
            for index, out in enumerate((*hidden, 1)):
                # MLP = Linear, ReLU, Linear, ..., Linear: the linears sit at even indices.
                shapes[f"head.{name}.{2 * index}.weight"] = (out, width)
                shapes[f"head.{name}.{2 * index}.bias"] = (out,)
                width = out
        return shapes


def _spec_of(network: Any) -> PolicySpec:
    """The header of a PyTorch TDRQN or DDRQN; refuses what the forward does not cover."""
    from spikectl.agents.per_neuron_networks import DDRQN, TDRQN

    if isinstance(network, TDRQN):
        architecture = "tdrqn"
    elif isinstance(network, DDRQN):
        architecture = "ddrqn"
    else:
        raise ValueError(
            f"export_policy: cannot compile a {type(network).__name__}; supported "
            f"architectures: {', '.join(SUPPORTED_ARCHITECTURES)} (make_agent's TDRQN and DDRQN)"
        )
    s = network.sizes
    if s.layer_norm:
        raise ValueError(
            "export_policy: the compiled policy has no LayerNorm in its MLPs "
            "(AgentSizes.layer_norm); play this network with PyTorch"
        )
    flags = compiled_input_flags(s.inputs)
    eps = 1e-5
    if architecture == "tdrqn":
        encoder = network.mixer.encoder
        layers = list(encoder.layers)
        if encoder.norm is not None or any(
            layer.norm_first or layer.activation_relu_or_gelu != 1 for layer in layers
        ):
            raise ValueError(
                "export_policy: the compiled TDRQN supports post-norm encoder layers with "
                "ReLU and no final norm (what make_agent builds)"
            )
        eps = float(layers[0].norm1.eps)
    return PolicySpec(
        architecture=architecture,
        n_neurons=int(network.n_neurons),
        episode_length=int(network.episode_length),
        v_rest_mV=float(network.v_rest_mV),
        v_threshold_mV=float(network.v_threshold_mV),
        lstm_hidden=s.lstm_hidden,
        target_embed=s.target_embed,
        pattern_embed=s.pattern_embed,
        mix_hidden=s.ff_hidden,
        attn_width=s.attn_width,
        attn_layers=s.attn_layers,
        attn_heads=s.attn_heads,
        attn_ff=s.attn_ff,
        layer_norm_eps=eps,
        head_hidden=tuple(s.tdrqn_head_hidden if architecture == "tdrqn" else s.head_hidden),
        value_hidden=tuple(s.value_hidden),
        do_nothing_head=s.do_nothing_head,
        **flags,
    )


def compiled_input_flags(inputs: tuple[str, ...]) -> dict[str, bool]:
    """The header's flags for a network's ``AgentSizes.inputs``; refuses features the
    compiled forward does not compute, or in another order than it computes them."""
    names = [name for name, _ in COMPILED_INPUTS]
    if any(name not in names for name in inputs) or list(inputs) != sorted(inputs, key=names.index):
        raise ValueError(
            f"export_policy: the compiled policy computes the input features "
            f"{', '.join(names)} (any of them, in that order); this network reads "
            f"{', '.join(inputs)}: play it with PyTorch"
        )
    return {flag: name in inputs for name, flag in COMPILED_INPUTS}


def _policy_bytes(network: Any) -> bytes:
    """The ``.npz`` file of a network, in memory."""
    spec = _spec_of(network)
    weights = {
        name: tensor.detach().cpu().float().numpy() for name, tensor in network.state_dict().items()
    }
    expected = spec.weight_shapes()
    shapes = {name: tuple(array.shape) for name, array in weights.items()}
    if shapes != expected:  # the exporter and the loader must agree on every weight
        raise ValueError(
            f"export_policy: the {spec.architecture} network's weights "
            f"{_mismatch(expected, shapes)}"
        )
    header = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, **asdict(spec)}
    header["checksum"] = policy_checksum(spec, weights)
    buffer = io.BytesIO()
    np.savez(buffer, **{HEADER_KEY: np.array(json.dumps(header))}, **weights)
    return buffer.getvalue()


_HASHED_WHEN_SET = ("proximity_in_input",)
"""Header fields added after the checksum: hashed only when set, so that the files
written before them still match."""


def policy_checksum(spec: PolicySpec, weights: Mapping[str, np.ndarray]) -> str:
    """SHA-256 over the header's values (as read, defaults filled in) and every weight's
    name, dtype, shape and bytes: a header changed over the same weights, or weights
    changed under the same header, no longer match."""
    header = asdict(spec)
    for name in _HASHED_WHEN_SET:  # files written before these fields hash without them
        if header[name] is False:
            del header[name]
    digest = hashlib.sha256(json.dumps(header, sort_keys=True).encode())
    for name in sorted(weights):
        array = np.ascontiguousarray(weights[name])
        digest.update(f"{name}|{array.dtype.str}|{array.shape}|".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def export_policy(network: Any, path: str | Path) -> Path:
    """Write a TDRQN or DDRQN to ``path`` (``.npz``), atomically, for
    :meth:`CompiledPolicy.load`. Returns the path. Other architectures raise
    ``ValueError`` naming the supported ones."""
    return atomic_write_bytes(path, _policy_bytes(network))


MAX_LISTED = 3
"""The most weights a shape mismatch lists by name (the rest are counted)."""


def _mismatch(expected: Mapping[str, tuple], actual: Mapping[str, tuple]) -> str:
    """What differs between two {name: shape} tables, in one line."""
    problems = []
    missing = sorted(set(expected) - set(actual))
    extra = sorted(set(actual) - set(expected))
    if missing:
        problems.append(f"lack {_listed(missing)}")
    if extra:
        problems.append(f"have unexpected {_listed(extra)}")
    for name in sorted(set(expected) & set(actual)):
        if tuple(expected[name]) != tuple(actual[name]):
            problems.append(
                f"{name} has shape {tuple(actual[name])}, the header says {tuple(expected[name])}"
            )
    if len(problems) > MAX_LISTED:
        problems = [*problems[:MAX_LISTED], f"and {len(problems) - MAX_LISTED} more"]
    return "; ".join(problems)


def _listed(names: list[str]) -> str:
    if len(names) <= MAX_LISTED:
        return str(names)
    return f"{names[:MAX_LISTED]} and {len(names) - MAX_LISTED} more"
