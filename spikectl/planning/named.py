"""The named controller ``identify-and-plan`` as data: one declared composition per suite
situation, and the rule that picks one for an environment.

Each composition was chosen on the suite's validation sets (docs/baselines.md, the
research record docs/research/identify-and-plan.md):

- ``paper``: the constructor's defaults (the paper's model).
- ``noise``: under measurement noise, the exact posterior under the task's observation
  model (``"bayes"``) with potentials filtered against the model.
- ``stochastic``: under stochastic release, the task's observation model (releases
  settled from the residuals, unrested inputs stimulated) and ``known_sd``
  :data:`KNOWN_SD_STOCHASTIC_RELEASE`: a failed release teaches little, and waiting for
  certainty costs wanted spikes.
- ``background``: under background input, ``known_sd`` :data:`KNOWN_SD_BACKGROUND`.
- ``heterogeneous``: the task's observation model (each neuron's threshold and leak
  learned, known synapses planned at their estimated strength).
- ``hidden``: with hidden neurons, the relays through them.
- ``chr2``: through the ChR2 actuator, with or without measurement noise, stochastic
  release, background input, heterogeneous or hidden neurons (the light is read by the
  paper's tracker alone, which the noise and heterogeneous compositions replace, so the
  light's situation comes before theirs), the exact posterior (``"bayes"``): with the
  light's ~10 ms of drive it knows more of the network at each step than the Gaussian
  estimate, with fewer probes (the research record docs/results/iap-chr2; with another
  extension it was not measured against that extension's composition, and no suite task
  combines them). Its fast form stays the paper's composition (:data:`FAST_AS_PAPER`).
- ``rig``: under spikes-only sensing with the ChR2 light or background input (suite
  v2's ``rig`` task), the posterior from spikes weighed by their likelihood under the
  task's background input, with the light's drive in each column's potential
  (:mod:`~spikectl.planning.spike_likelihood`, the task's model read, n <= 8; hidden or
  heterogeneous neurons, stochastic release and recorded subsets are refused in one
  line), each re-plan one light sequence for its mean return over
  :data:`RIG_HYPOTHESES` networks drawn from the posterior: planned on one network, the
  light drove bursts the estimate could not foresee (the research record
  docs/results/iap-rig). It comes first.
- ``spikes``: under spikes-only sensing, the exact posterior from spikes alone and the
  potentials it implies (:mod:`~spikectl.planning.spike_filter`, n <= 8; larger
  networks are refused in one line), with QMDP where it would probe (:data:`GAMBLE`):
  from spikes alone the estimate knows little for long, and valuing the gamble over
  networks drawn from it scores more (the research record docs/results/iap-spikes). It
  comes first: the filter refuses in one line the extensions it cannot read spikes
  under.

From :data:`LARGE_FROM_NEURONS` neurons on, each is played with :data:`LARGE` on top
(``-16``: QMDP where it would probe, ``known_sd`` :data:`KNOWN_SD_LARGE`); the paper's
situation from :data:`PARTICLES_FROM_NEURONS` on with the particle posterior as well
(``paper-32``). ``fast`` forms are what the guided learner's teacher plays (its labels
cover every step of training, so every decision must be fast): the same but for QMDP and
the particles, replaced from :data:`LARGE_FROM_NEURONS` on by :data:`KNOWN_SD_FAST_LARGE`
alone (``-16-fast``). Below that size the fast form is the named composition itself (the
paper's for the situations of :data:`FAST_AS_PAPER`), without QMDP where it has it
(``NAME-fast``: ``spikes-fast``).

The ``realtime`` forms (``NAME-realtime``, ``NAME-16-realtime``; the registered controller
``identify-and-plan-realtime``) are the fast forms re-planning at beam width
:data:`REALTIME_WIDTH`: what a rig stepping at 1 kHz can run at n = 8 and 16.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from spikectl.neuron.extensions import Extensions
from spikectl.planning.composition import Composition
from spikectl.planning.deciding import DecisionSettings
from spikectl.planning.estimators import EstimatorSettings
from spikectl.planning.observing import ObservationSettings
from spikectl.planning.qmdp import QMDPSettings

LARGE_FROM_NEURONS = 16
"""From this many neurons on, the named controller plays its situation's composition with
:data:`LARGE` (or :data:`FAST_LARGE`) on top: chosen on the ``n16`` and ``n32``
validation sets; at n = 8 QMDP costs about 5x the CPU time for a gain within noise."""
PARTICLES_FROM_NEURONS = 32
"""From this many neurons on, where the task's extensions ask for nothing of their own,
the named controller (not its fast form) keeps the particle posterior: chosen on the
``n32`` validation set with QMDP, where it also takes less CPU time; on ``n16`` it did not
score more (docs/results/particles)."""
GAMBLE_NETWORKS = 16
"""K, the networks QMDP draws from the estimate (:data:`GAMBLE`)."""
GAMBLE = QMDPSettings(networks=GAMBLE_NETWORKS)
"""QMDP where the plan would probe: from :data:`LARGE_FROM_NEURONS` neurons on, and in the
``spikes`` composition at every size."""
KNOWN_SD_LARGE = 0.35
"""``known_sd`` (w_in) from :data:`LARGE_FROM_NEURONS` neurons on: the generator's prior
already puts the synapses of pairs more than 8 neurons apart below it, so the planner
probes only the target's neighbours and plans sooner on what it knows (the best mean of
the ``n16`` and ``n32`` validation sets)."""
KNOWN_SD_FAST_LARGE = 0.4
"""``known_sd`` (w_in) of the fast form from :data:`LARGE_FROM_NEURONS` neurons on,
without QMDP: about as good as the QMDP setting at about a hundredth of its CPU time."""
KNOWN_SD_STOCHASTIC_RELEASE = 0.4
"""``known_sd`` (w_in) under stochastic release (the ``stochastic`` validation set)."""
KNOWN_SD_BACKGROUND = 0.35
"""``known_sd`` (w_in) under background input (the ``background`` validation set)."""

RIG_HYPOTHESES = 8
"""K, the networks the ``rig`` composition plans each light sequence on (drawn from the
spike likelihood's posterior): on the ``rig`` validation networks 8 scored above 1 and 4,
and 16 within noise of 8 at about twice the CPU time (docs/results/iap-rig)."""

REALTIME_WIDTH = 12
"""Beam width of the real-time forms: on the ``paper`` and ``n16`` validation sets widths
12 to 32 score the same within noise, and 12 is the widest that kept the 99th percentile
of a decision's CPU time under 1 ms at n = 16 in every timing run (the research record
docs/results/realtime-iap)."""

FAST_AS_PAPER = ("chr2",)
"""Situations whose fast form (the guided learner's teacher) is the paper's composition:
the ``chr2`` teacher's labels stay those its learners were trained on, at the Gaussian
estimate's CPU time."""

FAST_AS_EXACT_SPIKES = ("rig",)
"""Situations whose fast form is the exact spike filter's ``spikes-fast`` composition, which
refuses them in one line: the ``rig`` composition costs about 1 CPU second an episode
(docs/results/iap-rig), too slow to label every step of training, so the guided
learner's identify teacher stays refused there (train with ``--teacher oracle``)."""

_TASK_MODEL = ObservationSettings(task_model=True)

COMPOSITIONS: dict[str, Composition] = {
    composition.name: composition
    for composition in (
        Composition("paper"),
        Composition("noise", EstimatorSettings("bayes"),
                    ObservationSettings(task_model=True, filter_voltage=True)),
        Composition("stochastic", EstimatorSettings(known_sd=KNOWN_SD_STOCHASTIC_RELEASE),
                    _TASK_MODEL),
        Composition("background", EstimatorSettings(known_sd=KNOWN_SD_BACKGROUND)),
        Composition("heterogeneous", observation=_TASK_MODEL),
        Composition("hidden", EstimatorSettings("relays")),
        Composition("spikes", EstimatorSettings("spikes"),
                    decision=DecisionSettings(gamble=GAMBLE)),
        Composition("chr2", EstimatorSettings("bayes")),
        Composition("rig", EstimatorSettings("spike-likelihood"), _TASK_MODEL,
                    DecisionSettings(hypotheses=RIG_HYPOTHESES)),
    )
}  # fmt: skip
"""The situations' compositions by name (before a size's overlay)."""

SITUATIONS: tuple[tuple[str, tuple[str | tuple[str, ...], ...]], ...] = (
    ("rig", (("spikes_only", "lit"), ("spikes_only", "background_rate"))),
    ("spikes", ("spikes_only",)),
    ("chr2", ("lit",)),
    ("noise", ("observation_noise_mV",)),
    ("stochastic", ("stochastic_release",)),
    ("background", ("background_rate",)),
    ("heterogeneous", ("threshold_spread", "time_constant_spread", "synaptic_spread")),
    ("hidden", ("hidden_neurons", "hidden_fraction")),
)
"""(composition, the extension fields (or properties) that ask for it): an environment
plays the first situation one of whose fields is set (true or nonzero; a tuple of fields:
all of them set); none: ``paper``."""

LARGE = {"known_sd": KNOWN_SD_LARGE, "gamble": GAMBLE}
"""The overlay from :data:`LARGE_FROM_NEURONS` neurons on (suffix ``-16``)."""
LARGEST = {**LARGE, "kind": "particles"}
"""The overlay of the paper's situation from :data:`PARTICLES_FROM_NEURONS` on (``-32``)."""
FAST = {"gamble": None}
"""The fast forms' overlay below :data:`LARGE_FROM_NEURONS` neurons where the situation's
composition has QMDP (``-fast``)."""
FAST_LARGE = {**FAST, "known_sd": KNOWN_SD_FAST_LARGE}
"""The fast forms' overlay from :data:`LARGE_FROM_NEURONS` neurons on (``-16-fast``)."""
REALTIME = {**FAST, "width": REALTIME_WIDTH}
"""The real-time forms' overlay on the fast forms (``-realtime``, ``-16-realtime``)."""


def situation(extensions: Extensions | None) -> str:
    """The situation of an environment with ``extensions`` (:data:`SITUATIONS`)."""
    if extensions is not None:
        for name, fields in SITUATIONS:
            if any(_all_set(extensions, field) for field in fields):
                return name
    return "paper"


def _all_set(extensions: Extensions, fields: str | tuple[str, ...]) -> bool:
    """Whether the field, or every field of a tuple, is set (true or nonzero)."""
    names = (fields,) if isinstance(fields, str) else fields
    return all(getattr(extensions, name) for name in names)


def composition_name(extensions: Extensions | None, n_neurons: int | None = None,
                     fast: bool = False, realtime: bool = False) -> str:  # fmt: skip
    """The name of the composition the named controller plays on an environment with
    ``extensions`` and ``n_neurons`` observed neurons (``fast``: the teacher's form;
    ``realtime``: the fast form at :data:`REALTIME_WIDTH`): the situation's, with the
    size's suffix (``-16``, ``-16-fast``, ``-32``), ``-fast`` (a fast form below
    :data:`LARGE_FROM_NEURONS` without its situation's QMDP) or ``-realtime``."""
    name = situation(extensions)
    fast = fast or realtime
    if fast and name in FAST_AS_PAPER:
        name = "paper"
    if fast and name in FAST_AS_EXACT_SPIKES:
        name = "spikes"
    if n_neurons is None or n_neurons < LARGE_FROM_NEURONS:
        if realtime:
            return f"{name}-realtime"
        return f"{name}-fast" if fast and COMPOSITIONS[name].decision.gamble else name
    if fast:
        return f"{name}-16-realtime" if realtime else f"{name}-16-fast"
    if name == "paper" and n_neurons >= PARTICLES_FROM_NEURONS:
        return "paper-32"
    return f"{name}-16"


def composition(name: str) -> Composition:
    """The declared composition ``name``: a situation's (:data:`COMPOSITIONS`), or one
    with a size's overlay (``NAME-16``, ``NAME-16-fast``, ``paper-32``), a fast form's
    (``NAME-fast``) or a real-time form's (``NAME-realtime``, ``NAME-16-realtime``)."""
    base, _, size = name.partition("-")
    overlays = {"": {}, "fast": FAST, "16": LARGE, "16-fast": FAST_LARGE, "32": LARGEST,
                "realtime": REALTIME, "16-realtime": {**FAST_LARGE, **REALTIME}}  # fmt: skip
    if base not in COMPOSITIONS or size not in overlays or (size == "32" and base != "paper"):
        raise ValueError(f"unknown composition {name!r}; the named ones are "
                         f"{', '.join(COMPOSITIONS)}, each also -fast, -16, -16-fast, -realtime "
                         "and -16-realtime, and paper-32")  # fmt: skip
    return _overlaid(COMPOSITIONS[base], name, overlays[size])


def named_composition(extensions: Extensions | None, n_neurons: int | None = None,
                      fast: bool = False, realtime: bool = False) -> Composition:  # fmt: skip
    """What the named controller ``identify-and-plan`` plays on an environment with
    ``extensions`` and ``n_neurons`` observed neurons (``spikectl benchmark``,
    ``spikectl realtime``, ``spikectl.load_controller``); ``fast=True``: the form the
    guided learner's teacher plays; ``realtime=True``: what
    ``identify-and-plan-realtime`` plays."""
    return composition(composition_name(extensions, n_neurons, fast, realtime))


def _overlaid(base: Composition, name: str, overlay: dict[str, Any]) -> Composition:
    """``base`` named ``name`` with an overlay's estimator (``kind``, ``known_sd``) and
    decision (``gamble``, ``width``) settings."""
    estimator = {key: overlay[key] for key in ("kind", "known_sd") if key in overlay}
    decision = {key: overlay[key] for key in ("gamble", "width") if key in overlay}
    return base.but(name, estimator=dataclasses.replace(base.estimator, **estimator),
                    decision=dataclasses.replace(base.decision, **decision))  # fmt: skip
