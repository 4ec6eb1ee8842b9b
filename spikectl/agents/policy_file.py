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
import math
from collections.abc import Mapping
from dataclasses import MISSING, asdict, dataclass, fields
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
    # Fields added after format version 1 have a default: files written before them read
    # as that default.
    others_spiking_in_input: bool = False
    proximity_in_input: bool = False

    @property
    def input_features(self) -> int:
        """F: [v_norm, stimulated, (is target), (target's v_norm), (others spiking),
        (the target's proximity)]."""
        flags = self.target_in_input + self.target_voltage_in_input + self.others_spiking_in_input
        return 2 + flags + self.proximity_in_input

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
        target_in_input=s.target_in_input,
        target_voltage_in_input=s.target_voltage_in_input,
        others_spiking_in_input=s.others_spiking_in_input,
        proximity_in_input=s.proximity_in_input,
    )


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


def header_differences(spec: PolicySpec, shapes: Mapping[str, tuple[int, ...]]) -> list[str]:
    """Each header field the weights' shapes imply and that differs from the header, as
    'FIELD HEADER (the weights: VALUE)': the architecture first (alone: the rest then
    means other things), then the widths, depths and lengths."""
    implied = implied_by_weights(shapes)
    if implied.get("architecture", spec.architecture) != spec.architecture:
        names = ["architecture"]
    else:
        names = [name for name in implied if name != "architecture"]
    header = {**asdict(spec), "input features": spec.input_features}
    return [
        f"{name} {_shown(header[name])} (the weights: {_shown(implied[name])})"
        for name in names
        if name in implied and _shown(header[name]) != _shown(implied[name])
    ]


def implied_by_weights(shapes: Mapping[str, tuple[int, ...]]) -> dict[str, Any]:
    """The header fields a policy file's weight shapes determine (those it holds)."""

    def dimension(name: str, axis: int) -> int | None:
        shape = shapes.get(name)
        return shape[axis] if shape is not None and len(shape) > axis else None

    layers = {name.split(".")[3] for name in shapes if name.startswith("mixer.encoder.layers.")}
    implied: dict[str, Any] = {
        "architecture": "tdrqn" if layers else "ddrqn" if "ff.0.weight" in shapes else None,
        "lstm_hidden": dimension("lstm.lstm.weight_hh_l0", 1),
        "input features": dimension("lstm.lstm.weight_ih_l0", 1),
        "episode_length": dimension("context.pattern.0.weight", 1),
        "pattern_embed": dimension("context.pattern.0.weight", 0),
        "target_embed": dimension("context.target.0.weight", 0),
        "mix_hidden": dimension("ff.0.weight", 0),
        "attn_layers": len(layers) or None,
        "attn_width": dimension("mixer.encoder.layers.0.norm1.weight", 0),
        "attn_ff": dimension("mixer.encoder.layers.0.linear1.weight", 0),
    }
    for head, field_name in (("advantage", "head_hidden"), ("value", "value_hidden")):
        outs = []
        while f"head.{head}.{2 * len(outs)}.weight" in shapes:
            outs.append(dimension(f"head.{head}.{2 * len(outs)}.weight", 0))
        if outs:
            implied[field_name] = tuple(outs[:-1])  # the last layer is the output
    return {name: value for name, value in implied.items() if value is not None}


def _shown(value: Any) -> str:
    return str(list(value)) if isinstance(value, (list, tuple)) else str(value)


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


# The flat layout the kernel reads: every linear layer's W^T [in, out] and bias in one
# float32 buffer, and one row (W^T offset, bias offset, in, out) per layer in the order


def _parse_header(where: str, raw: np.ndarray) -> PolicySpec:
    try:
        header = json.loads(str(raw))
    except (json.JSONDecodeError, TypeError) as error:
        raise PolicyFileError(f"{where} has an unreadable header: {error}") from error
    except RecursionError:
        raise PolicyFileError(f"{where} has an unreadable header: nested too deeply") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
        raise PolicyFileError(f"{where} is not a compiled policy (no {FORMAT_NAME} header)")
    version = header.get("format_version")
    if version != FORMAT_VERSION:
        raise PolicyFileError(
            f"{where} has compiled-policy format version {version}; this spikectl reads "
            f"version {FORMAT_VERSION} (export the network again with export_policy)"
        )
    if header.get("architecture") not in SUPPORTED_ARCHITECTURES:
        raise PolicyFileError(
            f"{where} holds architecture {header.get('architecture')!r}; supported: "
            f"{', '.join(SUPPORTED_ARCHITECTURES)}"
        )
    required = [field.name for field in fields(PolicySpec) if field.default is MISSING]
    missing = [name for name in required if name not in header]
    if missing:
        raise PolicyFileError(f"{where}: the header lacks {missing}")
    values = {field.name: header.get(field.name, field.default) for field in fields(PolicySpec)}
    for field in fields(PolicySpec):
        value = values[field.name]
        if field.type == "int":
            ok = type(value) is int and value >= 1
        elif field.type == "float":
            ok = type(value) in (int, float) and math.isfinite(value)
        elif field.type == "bool":
            ok = type(value) is bool
        elif field.type == "tuple[int, ...]":
            ok = isinstance(value, list) and all(type(v) is int and v >= 1 for v in value)
            value = tuple(value) if ok else value
        else:
            ok = isinstance(value, str)
        if not ok:
            raise PolicyFileError(f"{where}: the header's {field.name} is {value!r}")
        values[field.name] = value
    if values["do_nothing_head"] not in ("dueling", "pooled"):
        raise PolicyFileError(
            f"{where}: do_nothing_head {values['do_nothing_head']!r} is not 'dueling' or 'pooled'"
        )
    if values["attn_width"] % values["attn_heads"] or values["layer_norm_eps"] <= 0:
        raise PolicyFileError(
            f"{where}: attn_heads {values['attn_heads']} must divide attn_width "
            f"{values['attn_width']}, and layer_norm_eps {values['layer_norm_eps']} be > 0"
        )
    _check_ranges(where, values)
    return PolicySpec(**values)


def _check_ranges(where: str, values: dict[str, Any]) -> None:
    """Sizes and potentials within what a network can be: checked before anything of
    those sizes is allocated (a header claiming 10^9 neurons is one line, not 4 GB)."""
    from spikectl.contexts.generation import MAX_EPISODE_LENGTH, MAX_N_NEURONS

    limits = {"n_neurons": MAX_N_NEURONS, "episode_length": MAX_EPISODE_LENGTH,
              "attn_layers": 64, "attn_heads": MAX_WIDTH}  # fmt: skip
    for name, value in values.items():
        widths = value if isinstance(value, tuple) else (value,)
        most = limits.get(name, MAX_WIDTH)
        if type(value) in (int, tuple) and any(width > most for width in widths):
            raise PolicyFileError(f"{where}: the header's {name} is {value!r}, above {most}")
    if values["n_neurons"] < 2 or values["episode_length"] < 2:
        raise PolicyFileError(f"{where}: the header's n_neurons and episode_length must be >= 2")
    rest, threshold = values["v_rest_mV"], values["v_threshold_mV"]
    if not (abs(rest) <= MAX_POTENTIAL_MV and abs(threshold) <= MAX_POTENTIAL_MV):
        raise PolicyFileError(
            f"{where}: the header's v_rest_mV {rest!r} or v_threshold_mV {threshold!r} is "
            f"beyond +-{MAX_POTENTIAL_MV:g} mV"
        )
    if not threshold > rest:
        raise PolicyFileError(
            f"{where}: the header's v_threshold_mV {threshold!r} must be above v_rest_mV {rest!r}"
        )
    if not values["layer_norm_eps"] < 1:
        raise PolicyFileError(
            f"{where}: the header's layer_norm_eps {values['layer_norm_eps']!r} must be < 1"
        )


def check_policy_checksum(where: str, header_raw: np.ndarray, spec: PolicySpec,
                          weights: Mapping[str, np.ndarray]) -> None:  # fmt: skip
    """Refuse a file whose header or weights changed since export (checksum mismatch)."""
    header = json.loads(str(header_raw))
    if header.get("checksum") != policy_checksum(spec, weights):
        raise PolicyFileError(
            f"{where} is damaged or altered: its checksum does not match its header and weights"
        )
