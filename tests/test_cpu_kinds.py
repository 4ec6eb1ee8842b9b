"""The training-free controllers decide the same on every CPU kind (issue 58).

One machine stands in for the others: NumPy's SIMD dispatch is narrowed with
``NPY_DISABLE_CPU_FEATURES``, Numba compiles for another CPU with ``NUMBA_CPU_NAME`` and
OpenBLAS runs another CPU's kernels with ``OPENBLAS_CORETYPE``. Each test plays the
planners in a subprocess under each emulation the machine can run and compares every
action and every posterior the planner computed with the native run's. The planners'
floats go through :mod:`spikectl.planning.portable`, whose results do not depend on the
CPU's kernels, so the comparison is exact by design (not two kernels compared bit for
bit): a NumPy ``np.exp`` or a BLAS product back in a decision path makes it fail on any
machine where an emulation changes that kernel (AVX-512 machines: NumPy's exp and log;
every machine: OpenBLAS's Nehalem kernels sum in another order than its native ones).
"""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spikectl.planning import portable

# Plays identify-and-plan (each case's settings) on the first networks of a suite task's
# test set and prints, per network, its actions and a digest of every posterior its
# estimate gave (mean and sd, every step).
PLAY = r"""
import hashlib, json, sys
import numpy as np
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.planning import EstimatorSettings, QMDPSettings, named_composition, policy

cases = json.loads(sys.argv[1])
act = policy.IdentifyAndPlan.act
seen = {}

def recording_act(self, observation, info):
    action = act(self, observation, info)
    mean, sd = self.estimate.posterior()
    digest = hashlib.sha256(np.ascontiguousarray(mean).tobytes() + sd.tobytes()).hexdigest()
    seen.setdefault(self.seed, []).append([action, digest[:16]])
    return action

policy.IdentifyAndPlan.act = recording_act
result = {}
for name, task, count, settings in cases:
    version = settings.get("suite", 1)
    spec = suite.task(task, version)
    contexts = suite.load_split(task, "test", version)[:count]
    # As load_controller builds the named controller, with the case's parts on top.
    composition = named_composition(spec.extensions, spec.n_observed)
    if "estimator" in settings:
        composition = composition.but(name, estimator=EstimatorSettings(settings["estimator"]))
    if "gamble_networks" in settings:
        gamble = QMDPSettings(networks=settings["gamble_networks"])
        composition = composition.but(name, decision=composition.decision.__class__(gamble=gamble))
    controller = policy.IdentifyAndPlan(contexts.params, composition, extensions=spec.extensions)
    seen.clear()
    returns = evaluate_policy(contexts, controller, extensions=spec.extensions, seed=0).returns
    result[name] = {"returns": returns.tolist(), "steps": {str(k): v for k, v in seen.items()}}
# The environment's own float tables: bleaching's decay over an episode.
from spikectl.neuron.extensions import EnvironmentEffects, Extensions
from spikectl.neuron.params import NeuronParams
for tau in (30.0, 77.0, 400.0):
    effects = EnvironmentEffects(Extensions(bleaching_time_constant_steps=tau), NeuronParams(), 60)
    result[f"bleaching-{tau}"] = hashlib.sha256(effects.bleaching.tobytes()).hexdigest()
print("RESULT" + json.dumps(result))
"""

CASES = [
    # name, suite task, networks, parts beyond the named controller's
    ("bayes-filtered", "noise2", 4, {}),
    ("gaussian", "paper", 4, {}),
    ("particles-qmdp", "paper", 3, {"estimator": "particles", "gamble_networks": 4}),
    ("stochastic-release", "stochastic", 4, {}),
    ("relays", "hidden25", 4, {}),
    ("spikes", "spikes-only", 4, {"suite": 2}),
]


def _numpy_dispatch(wider_than_avx2: bool) -> list[str]:
    """The SIMD targets NumPy dispatches to on this CPU: those beyond AVX2 (AVX-512), or
    every one from AVX2 on; [] where the CPU has none of them."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    avx512 = [name for name in __cpu_dispatch__ if "AVX512" in name or name == "X86_V4"]
    avx2 = [name for name in __cpu_dispatch__ if name in ("X86_V3", "AVX2", "FMA3", "F16C")]
    chosen = avx512 if wider_than_avx2 else avx512 + avx2
    return [name for name in chosen if __cpu_features__.get(name)]


def _emulations() -> dict[str, dict[str, str]]:
    """The CPU kinds this machine can stand in for: name -> environment variables."""
    kinds: dict[str, dict[str, str]] = {}
    avx512 = _numpy_dispatch(wider_than_avx2=True)
    if avx512:
        kinds["numpy-without-avx512"] = {"NPY_DISABLE_CPU_FEATURES": " ".join(avx512)}
    up_to_avx2 = _numpy_dispatch(wider_than_avx2=False)
    if up_to_avx2 and up_to_avx2 != avx512:
        kinds["numpy-without-avx2"] = {"NPY_DISABLE_CPU_FEATURES": " ".join(up_to_avx2)}
    kinds["numba-haswell"] = {"NUMBA_CPU_NAME": "haswell"}
    kinds["openblas-nehalem"] = {"OPENBLAS_CORETYPE": "Nehalem"}
    kinds["openblas-haswell"] = {"OPENBLAS_CORETYPE": "Haswell"}
    if avx512:
        kinds["avx2-machine"] = {
            "NPY_DISABLE_CPU_FEATURES": " ".join(avx512),
            "NUMBA_CPU_NAME": "haswell",
            "OPENBLAS_CORETYPE": "Zen",
        }
    return kinds


def _play(extra_environment: dict[str, str]) -> dict:
    environment = {**os.environ, "OMP_NUM_THREADS": "1", **extra_environment}
    for name in ("NPY_DISABLE_CPU_FEATURES", "NUMBA_CPU_NAME", "OPENBLAS_CORETYPE"):
        if name not in extra_environment:
            environment.pop(name, None)
    completed = subprocess.run(
        [sys.executable, "-c", PLAY, json.dumps(CASES)],
        env=environment, capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert completed.returncode == 0, completed.stderr[-3000:]
    line = next(row for row in completed.stdout.splitlines() if row.startswith("RESULT"))
    return json.loads(line[len("RESULT") :])


@pytest.fixture(scope="module")
def native() -> dict:
    return _play({})


@pytest.mark.slow
@pytest.mark.parametrize("kind", sorted(_emulations()))
def test_planner_decides_the_same_under_every_cpu_kind(native, kind):
    emulated = _play(_emulations()[kind])
    for name, _, count, _ in CASES:
        mine, theirs = native[name], emulated[name]
        for network in range(count):
            ours, other = mine["steps"][str(network)], theirs["steps"][str(network)]
            pairs = enumerate(zip(ours, other, strict=False))
            first = next((step for step, (mine_now, theirs_now) in pairs
                          if mine_now != theirs_now), None)  # fmt: skip
            assert first is None and len(ours) == len(other), (
                f"{name}, network {network}, under {kind}: the planner's posterior or action "
                f"first differs from the native run's at step {first} "
                f"(native {ours[first] if first is not None else ours[-1]}, "
                f"{kind} {other[first] if first is not None else other[-1]})"
            )
        assert mine["returns"] == theirs["returns"], (name, kind)
    bleaching = [key for key in native if key.startswith("bleaching-")]
    assert bleaching and all(native[key] == emulated[key] for key in bleaching), (
        f"the bleaching decay differs under {kind}"
    )


# The portable operations themselves, on inputs where NumPy's own kernels differ across
# CPUs in the last bit; compared with NumPy to the rounding of one operation.


def test_portable_elementwise_functions_match_numpy_to_rounding():
    values = np.random.default_rng(0).normal(size=(7, 300)) * 20
    positive = np.abs(values) + 1e-3
    for mine, numpy_function, argument in (
        (portable.exp, np.exp, values), (portable.expm1, np.expm1, values),
        (portable.log, np.log, positive), (portable.log1p, np.log1p, positive),
    ):  # fmt: skip
        result = mine(argument)
        assert result.shape == argument.shape and result.dtype == np.float64
        np.testing.assert_allclose(result, numpy_function(argument), rtol=4e-16, atol=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        edges = np.array([0.0, -1.0, np.inf, -np.inf, np.nan])
        np.testing.assert_array_equal(portable.log(edges), np.log(edges))
        np.testing.assert_array_equal(portable.log1p(edges - 1.0), np.log1p(edges - 1.0))
        np.testing.assert_array_equal(portable.exp(edges * 800), np.exp(edges * 800))
        pairs = np.array([[0.0, 1.0], [-np.inf, -np.inf], [np.inf, np.inf], [3.0, -50.0]])
        np.testing.assert_allclose(portable.logaddexp(pairs[:, 0], pairs[:, 1]),
                                   np.logaddexp(pairs[:, 0], pairs[:, 1]), rtol=1e-15)  # fmt: skip
    assert portable.exp(0.0) == 1.0  # a scalar gives a float


def test_portable_matmul_follows_numpy_shapes_and_sums_in_index_order():
    rng = np.random.default_rng(1)
    stack, matrix, vector = rng.normal(size=(4, 3, 5)), rng.normal(size=(5, 2)), rng.normal(size=5)
    pairs = (
        (stack, matrix),
        (stack, vector),
        (vector, matrix),
        (vector, vector),
        (matrix.T, stack.transpose(0, 2, 1)),
        (stack[:, None], np.stack([matrix, 2 * matrix])[None]),
    )
    for left, right in pairs:
        np.testing.assert_allclose(portable.matmul(left, right), np.matmul(left, right),
                                   rtol=1e-12, atol=1e-12)  # fmt: skip
    # The order is the index order: 1e16 + 1 - 1e16 is 0 summed left to right.
    assert portable.matmul(np.array([1e16, 1.0, -1e16]), np.ones(3)) == 0.0
    assert portable.matmul(np.array([1e16, -1e16, 1.0]), np.ones(3)) == 1.0
    with pytest.raises(ValueError, match="do not align"):
        portable.matmul(stack, stack)


def test_portable_spd_inverse_inverts_and_refuses_an_indefinite_matrix():
    rng = np.random.default_rng(2)
    factors = rng.normal(size=(6, 9, 9))
    precision = factors @ factors.transpose(0, 2, 1) + 9 * np.eye(9)
    inverse = portable.spd_inverse(precision)
    np.testing.assert_allclose(inverse, np.linalg.inv(precision), rtol=1e-10, atol=1e-14)
    np.testing.assert_array_equal(inverse, inverse.transpose(0, 2, 1))  # exactly symmetric
    with pytest.raises(ValueError, match="not symmetric positive definite"):
        portable.spd_inverse(np.diag([1.0, -1.0]))
    with pytest.raises(ValueError, match="square"):
        portable.spd_inverse(np.ones((2, 3)))



def _dense_spd_inverse(matrix: np.ndarray) -> np.ndarray:
    """The dense Cholesky inverse in the index order portable.spd_inverse promises, every
    sum over every index (plain Python floats: IEEE double, no fused operations)."""
    size = matrix.shape[0]
    lower = [[0.0] * size for _ in range(size)]
    inverse_lower = [[0.0] * size for _ in range(size)]
    for j in range(size):
        total = float(matrix[j, j])
        for k in range(j):
            total -= lower[j][k] * lower[j][k]
        lower[j][j] = math.sqrt(total)
        for i in range(j + 1, size):
            total = float(matrix[i, j])
            for k in range(j):
                total -= lower[i][k] * lower[j][k]
            lower[i][j] = total / lower[j][j]
    for j in range(size):
        inverse_lower[j][j] = 1.0 / lower[j][j]
        for i in range(j + 1, size):
            total = 0.0
            for k in range(j, i):
                total -= lower[i][k] * inverse_lower[k][j]
            inverse_lower[i][j] = total / lower[i][i]
    out = np.empty((size, size))
    for i in range(size):
        for j in range(i + 1):
            total = 0.0
            for k in range(i, size):
                total += inverse_lower[k][i] * inverse_lower[k][j]
            out[i, j] = out[j, i] = total
    return out


def test_portable_spd_inverse_of_a_posterior_precision_is_the_dense_one_bit_for_bit():
    """A posterior's precision is diagonal but for the neurons seen to release: the sums
    skip the other indices' exact zeros and must still give every bit of the dense sums."""
    rng = np.random.default_rng(5)
    for _ in range(40):
        n = int(rng.integers(1, 12))
        precision = np.zeros((3, n, n))
        precision[:, np.arange(n), np.arange(n)] = rng.uniform(1.0, 1e9, (3, n))
        for matrix in precision:
            releasing = rng.random(n) < rng.uniform(0.0, 0.8)
            for _ in range(int(rng.integers(0, 8))):
                released = (releasing & (rng.random(n) < 0.5)) * rng.choice([1.0, 0.3], n)
                matrix += np.outer(released, released) * 1e4
        expected = np.stack([_dense_spd_inverse(matrix) for matrix in precision])
        assert portable.spd_inverse(precision).tobytes() == expected.tobytes()

def test_gaussian_posterior_is_spd_inverse_then_matmul_bit_for_bit():
    """The fused posterior the Gaussian estimate reads gives the bits of its parts:
    portable.spd_inverse, portable.matmul of the moments, the diagonal's square root."""
    rng = np.random.default_rng(6)
    for _ in range(20):
        n = int(rng.integers(1, 12))
        precision = np.zeros((n, n, n))
        precision[:, np.arange(n), np.arange(n)] = rng.uniform(1.0, 10.0, (n, n))
        released = (rng.random((5, n)) < 0.4) * 1.0
        moment = rng.normal(size=(n, n))
        for row in released:
            precision += np.outer(row, row) * 1e4
        covariance = portable.spd_inverse(precision)
        mean, sd = portable.gaussian_posterior(precision, moment)
        assert mean.tobytes() == portable.matmul(covariance, moment[:, :, None])[:, :, 0].tobytes()
        assert sd.tobytes() == np.sqrt(np.diagonal(covariance, axis1=1, axis2=2)).tobytes()
    with pytest.raises(ValueError, match="not symmetric positive definite"):
        portable.gaussian_posterior(-np.eye(2)[None], np.zeros((1, 2)))
    with pytest.raises(ValueError, match="precisions"):
        portable.gaussian_posterior(np.eye(2)[None], np.zeros((1, 3)))


def test_add_evidence_is_numpys_update_bit_for_bit():
    from spikectl.planning.identify import add_evidence

    rng = np.random.default_rng(7)
    for _ in range(20):
        n, m = int(rng.integers(1, 10)), int(rng.integers(1, 20))
        precision, moment = rng.normal(size=(n, m, m)), rng.normal(size=(n, m))
        observed = rng.random(n) < 0.6
        regressors = rng.random(m) * (rng.random(m) < 0.5)
        residual, weight = rng.normal(size=n), float(rng.uniform(1.0, 1e4))
        expected_precision, expected_moment = precision.copy(), moment.copy()
        expected_precision[observed] += np.outer(regressors, regressors) * weight
        expected_moment[observed] += residual[observed, None] * regressors[None, :] * weight
        add_evidence(precision, moment, observed, regressors, residual, weight)
        assert precision.tobytes() == expected_precision.tobytes()
        assert moment.tobytes() == expected_moment.tobytes()


def test_planned_signs_are_the_rounded_known_means_under_dales_law():
    """ConnectivityEstimate.weights against its definition in NumPy, on random posteriors
    (means at the rounding's ties included)."""
    from spikectl.planning.identify import ConnectivityEstimate

    rng = np.random.default_rng(8)
    for _ in range(200):
        n = int(rng.integers(1, 17))
        mean = rng.normal(scale=rng.uniform(0.1, 2.0), size=(n, n))
        mean[rng.random((n, n)) < 0.2] = rng.choice([-1.5, -0.5, 0.5, 1.5])
        sd = rng.uniform(0.0, 0.5, (n, n))
        estimate = ConnectivityEstimate(n, 0.01)
        estimate._cache = (mean, sd)  # the posterior the weights are read from
        known = sd < 0.3
        expected = np.where(known, np.clip(np.rint(mean), -1, 1), 0.0)
        row_sign = np.sign(expected.sum(axis=1, keepdims=True))
        expected = np.where((row_sign != 0) & (expected != row_sign), 0.0, expected)
        signs, planned_known = estimate.weights(0.3)
        assert signs.dtype == np.int8 and np.array_equal(signs, expected)
        assert np.array_equal(planned_known, known)


# The committed suite tables are the golden record of every CPU kind: the training-free
# controllers' returns no longer depend on the CPU, so a few networks played again here
# must give the committed per-network returns. Only tasks whose environment draws nothing
# (no noise, stochastic release or background input) are replayed network by network: on
# the others a network's draws depend on the whole batch it is played in.
SUITE = Path(__file__).resolve().parents[1] / "docs" / "results" / "suite"
REPLAYED = [("paper", 6), ("hidden25", 4), ("heterogeneous", 4)]


def _committed_returns(task: str) -> np.ndarray:
    with open(SUITE / "identify-and-plan-per-network.csv", newline="") as file:
        rows = [row for row in csv.DictReader(file) if row["task"] == task]
    return np.array([float(row["return"]) for row in sorted(rows, key=lambda r: int(r["context"]))])


def _replay(task: str, count: int) -> np.ndarray:
    from spikectl.envs.env import NeuronControlEnv
    from spikectl.envs.rollout import evaluate_policy
    from spikectl.experiments import suite
    from spikectl.training.loaders import load_controller

    contexts = suite.load_split(task, "test")[:count]
    extensions = suite.task(task).extensions
    controller = load_controller(
        "identify-and-plan", env=NeuronControlEnv(contexts=contexts, extensions=extensions)
    )
    return evaluate_policy(contexts, controller, extensions=extensions, seed=0).returns


@pytest.mark.parametrize(("task", "count"), REPLAYED)
def test_identify_and_plan_replays_the_committed_suite_returns(task, count):
    # A changed decision moves a return by at least one step's reward (~0.01); 1e-9 allows
    # only the rounding of the return's own sum.
    np.testing.assert_allclose(_replay(task, count), _committed_returns(task)[:count],
                               rtol=0, atol=1e-9)  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize(("task", "count"), [("n16", 3), ("n32", 1)])
def test_identify_and_plan_replays_the_committed_returns_of_larger_networks(task, count):
    # n32's first network is one of the 23 of 100 whose committed return changed when the
    # planners' floats stopped depending on the CPU (0.659 -> 0.690).
    np.testing.assert_allclose(_replay(task, count), _committed_returns(task)[:count],
                               rtol=0, atol=1e-9)  # fmt: skip
