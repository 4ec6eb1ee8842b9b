"""Reading a compiled policy's header (``spikectl.agents.policy_file``): every value's
type and range checked before anything of its sizes is allocated, the checksum over the
header and the weights, and which header fields the weights' shapes contradict."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import MISSING, asdict, fields
from typing import Any

import numpy as np

from spikectl.agents.policy_file import (
    FORMAT_NAME,
    FORMAT_VERSION,
    MAX_POTENTIAL_MV,
    MAX_WIDTH,
    SUPPORTED_ARCHITECTURES,
    PolicyFileError,
    PolicySpec,
    policy_checksum,
)


def parse_header(where: str, raw: np.ndarray) -> PolicySpec:
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
