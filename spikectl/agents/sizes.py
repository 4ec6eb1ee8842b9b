"""The networks' sizes and settings (:class:`AgentSizes`, the paper's Table 2 by default)
and the architectures' names."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, ClassVar, Literal, get_args

from spikectl.agents.heads import PerNeuronQHead
from spikectl.agents.inputs import input_feature
from spikectl.config_errors import ConfigError
from spikectl.registry import RegistryError

Architecture = Literal["drqn", "ddrqn", "dmdrqn", "tdrqn"]
"""The architectures' names (the paper's order); ``AGENTS`` maps them to classes."""
ARCHITECTURES: tuple[str, ...] = get_args(Architecture)


@dataclass(frozen=True)
class AgentSizes:
    """Sizes and settings of the networks; defaults are the paper's Table 2 (docs/agents.md).

    The fields marked "not in the paper" are this project's choices (docs/agents.md).
    """

    lstm_hidden: int = 128
    """Memory hidden size: LSTM width (per neuron, or of the one system LSTM in DRQN)."""
    target_embed: int = 16
    """Width of the target-neuron code (FF + ReLU); half of the context size 32."""
    pattern_embed: int = 16
    """Width of the shifted-pattern code (FF + ReLU); half of the context size 32."""
    ff_hidden: int = 512
    """Non-transformer FF width: the transformer's stand-in in DDRQN (per neuron) and DMDRQN."""
    head_hidden: tuple[int, ...] = (512, 256, 128)
    """Final FF head widths of DRQN, DDRQN and DMDRQN."""
    tdrqn_head_hidden: tuple[int, ...] = (256, 128)
    """Final FF head widths of TDRQN (Table 2: the 512 layer is not in TDRQN)."""
    attn_width: int = 128
    """Attention hidden size (model width) of TDRQN's transformer encoder."""
    attn_layers: int = 2
    """Number of transformer encoder layers in TDRQN."""
    attn_heads: int = 1
    """Attention heads per layer in TDRQN (must divide attn_width)."""
    attn_ff: int = 256
    """Feed-forward width inside each transformer encoder layer."""
    value_hidden: tuple[int, ...] = (128,)
    """Widths of the pooled do-nothing value MLP of DDRQN and TDRQN (not in the paper)."""
    do_nothing_head: str = "dueling"
    """DDRQN/TDRQN do-nothing Q: 'dueling' (Q_i = V + A_i) or 'pooled' (Q_i = A_i); not in paper."""
    inputs: tuple[str, ...] = ("target",)
    """The per-neuron networks' input features after each neuron's voltage and whether it
    was stimulated, in order: names registered in ``spikectl.agents.inputs`` (``target``,
    ``target-voltage``, ``others-spiking``, ``proximity``, ...); ``()`` is the
    paper-literal input, where the target enters only after the memory."""
    layer_norm: bool = False
    """LayerNorm in every hidden layer of the Q heads and FF blocks (PQN; not in the paper)."""

    removed_fields: ClassVar[dict[str, tuple[Any, str]]] = {
        "belief_in_input": (
            False, "the planner's belief as input measured no change, docs/results/belief-input"
        ),
        "advice_in_input": (
            False, "with the planner's advice as input the student copies the planner, "
            "docs/results/advice-input",
        ),
    }  # fmt: skip
    """Fields of earlier versions' configs, with the value under which a run ran as
    today's (read by ``spikectl.training.config.Experiment.from_dict``)."""

    def __post_init__(self) -> None:
        for field in fields(self):
            value = getattr(self, field.name)
            if field.type == "int":
                if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                    raise ConfigError(field.name, f"must be an int >= 1, got {value!r}",
                                      label=f"AgentSizes.{field.name}")  # fmt: skip
            elif field.type == "tuple[int, ...]":
                if isinstance(value, int) or not all(
                    isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value
                ):
                    raise ConfigError(
                        field.name, f"must be a sequence of ints >= 1, got {value!r}",
                        label=f"AgentSizes.{field.name}",
                    )  # fmt: skip
                object.__setattr__(self, field.name, tuple(value))
        if self.attn_width % self.attn_heads:
            raise ConfigError(
                "attn_heads", f"({self.attn_heads}) must divide "
                f"AgentSizes.attn_width ({self.attn_width})", label="AgentSizes.attn_heads",
            )  # fmt: skip
        if self.do_nothing_head not in PerNeuronQHead.MODES:
            raise ConfigError(
                "do_nothing_head", f"must be one of {PerNeuronQHead.MODES}, got "
                f"{self.do_nothing_head!r}", label="AgentSizes.do_nothing_head",
            )  # fmt: skip
        if not isinstance(self.layer_norm, bool):
            raise ConfigError("layer_norm", f"must be a bool, got {self.layer_norm!r}",
                              label="AgentSizes.layer_norm")  # fmt: skip
        self._check_inputs()

    def _check_inputs(self) -> None:
        inputs = self.inputs
        if isinstance(inputs, str) or not all(isinstance(name, str) for name in inputs):
            raise ConfigError("inputs", f"must be a sequence of feature names, got {inputs!r}",
                              label="AgentSizes.inputs")  # fmt: skip
        object.__setattr__(self, "inputs", tuple(inputs))
        for name in self.inputs:
            try:
                input_feature(name)
            except (RegistryError, TypeError) as error:
                raise ConfigError("inputs", str(error), label="AgentSizes.inputs:") from None
        repeated = sorted({name for name in self.inputs if self.inputs.count(name) > 1})
        if repeated:
            raise ConfigError("inputs", f"names {', '.join(repeated)} more than once",
                              label="AgentSizes.inputs")  # fmt: skip

    def check_architecture(self, arch: str) -> None:
        """Refuse the settings ``arch`` does not read: DRQN reads no per-neuron input
        feature (those that predate the registry it ignores, ``InputFeature.drqn_ignores``)."""
        if arch != "drqn":
            return
        for name in self.inputs:
            if not input_feature(name).drqn_ignores:
                raise ConfigError(
                    "inputs", f"{name!r} is read by the per-neuron networks (ddrqn, dmdrqn, "
                    "tdrqn), not by drqn", label="AgentSizes.inputs:",
                )  # fmt: skip


INPUT_FLAGS = (
    ("target_in_input", "target", True),
    ("target_voltage_in_input", "target-voltage", False),
    ("others_spiking_in_input", "others-spiking", False),
    ("proximity_in_input", "proximity", False),
)
"""The booleans that chose the input features before ``AgentSizes.inputs``: (field, the
feature it switched on, its default), in the order the features were computed."""


def inputs_from_flags(values: dict[str, Any]) -> None:
    """Read a saved config's ``agent.sizes`` (``values``, changed in place) written before
    ``AgentSizes.inputs``: its input booleans become the features they switched on, in
    the order the network computed them (CHANGELOG: old configs migrate)."""
    flags = {name: values.pop(name) for name, _, _ in INPUT_FLAGS if name in values}
    if not flags:
        return
    if "inputs" in values:
        raise ConfigError(
            ("agent", "sizes", "inputs"), f"and the older {', '.join(flags)} cannot both be "
            "given (inputs names the features now)", label="sizes.inputs",
        )  # fmt: skip
    for name, value in flags.items():
        if not isinstance(value, bool):
            raise ConfigError(("agent", "sizes", name), f"must be a bool, got {value!r}",
                              label=f"sizes.{name}")  # fmt: skip
    values["inputs"] = [feature for name, feature, default in INPUT_FLAGS
                        if flags.get(name, default)]  # fmt: skip
