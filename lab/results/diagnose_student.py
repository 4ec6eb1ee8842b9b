"""Where a trained student loses to identify-and-plan: measured on the validation networks.

    python lab/results/diagnose_student.py RUN_DIR [RUN_DIR ...] [--model final|best]

Plays identify-and-plan and each run's greedy network on the 100 validation networks of
make_splits(100, 100, seed=0, n_val=100) (never the test set), splits each controller's
loss (1 - return) into missed wanted spikes and unwanted spikes by episode step (as
docs/results/baselines/diagnose_identify.py, at commit 6a705d8, does for the planner),
and, with the planner
played beside the student's own episodes, counts by step how often the two agree and how
often the student does nothing where the planner acts.
"""

import argparse

import numpy as np
import torch

from spikectl import IdentifyAndPlan, make_splits
from spikectl.envs.controller import Copies
from spikectl.envs.env_support import step_rewards
from spikectl.envs.rollout import evaluate_policy
from spikectl.training.loaders import load_controller

STEP_BINS = (0, 5, 10, 20, 30, 60)
DO_NOTHING = -1


class BesidePlanner:
    """The student acts; identify-and-plan (a copy per network) reads the same
    observations (which include the action taken) and says what it would have done at
    every step, and whether that is a probe (the copy's ``probes`` counter moves).
    ``steps`` holds (step, chosen [S], planned [S], probed [S]) per step."""

    def __init__(self, student) -> None:
        self.student, self.planner = student, Copies(IdentifyAndPlan())
        self.steps: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []

    def reset(self) -> None:
        self.student.reset()
        self.planner.reset()

    def act_batch(self, observations, infos) -> np.ndarray:
        chosen = self.student.act_batch(observations, infos)  # [S]
        before = np.array([copy.probes for copy in self.planner.copies] or [0] * len(chosen))
        planned = self.planner.act_batch(observations, infos)  # [S]
        probed = np.array([copy.probes for copy in self.planner.copies]) > before
        self.steps.append((int(observations["step"][0]), chosen, planned, probed))
        return chosen

    def act(self, observation, info) -> int:
        raise NotImplementedError("played on the vector environment only")


def loss_by_step(episodes, contexts) -> list[tuple[float, float]]:
    """(missed wanted spikes, unwanted spikes) per step bin, mean over networks."""
    patterns = np.stack([context.pattern for context in contexts])  # [S, N]
    targets = np.array([context.target for context in contexts])
    if_spike, if_silent = step_rewards(patterns)
    spikes = episodes.spikes[np.arange(len(contexts)), :, targets]  # [S, N]
    missed = np.where(patterns & ~spikes, if_spike, 0.0)
    unwanted = np.where(~patterns & spikes, if_silent, 0.0)
    return [
        (missed[:, low:high].sum() / len(contexts), unwanted[:, low:high].sum() / len(contexts))
        for low, high in zip(STEP_BINS[:-1], STEP_BINS[1:], strict=True)
    ]


def print_split(name: str, returns: np.ndarray, split) -> None:
    cells = "  ".join(f"{missed:.3f}/{unwanted:.3f}" for missed, unwanted in split)
    print(f"{name:<34}{returns.mean():.3f}   {cells}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+")
    parser.add_argument("--model", default="final", choices=("final", "best"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    _, _, contexts = make_splits(100, 100, seed=0, n_val=100)
    planner = evaluate_policy(contexts, IdentifyAndPlan())
    ranges = list(zip(STEP_BINS[:-1], STEP_BINS[1:], strict=True))
    bins = "  ".join(f"{low}-{high - 1:<6}" for low, high in ranges)
    print(f"{'loss missed/unwanted by step':<34}return  {bins}")
    print_split("identify-and-plan", planner.returns, loss_by_step(planner, contexts))
    for run in args.runs:
        beside = BesidePlanner(load_controller(run, model=args.model))
        episodes = evaluate_policy(contexts, beside)
        print_split(run, episodes.returns, loss_by_step(episodes, contexts))
        difference = episodes.returns - planner.returns
        print(
            f"  per network minus the planner: {difference.mean():+.3f}; better on "
            f"{(difference > 0.01).sum()}, worse on {(difference < -0.01).sum()} networks"
        )
        for low, high in zip(STEP_BINS[:-1], STEP_BINS[1:], strict=True):
            chosen = np.concatenate([c for step, c, _, _ in beside.steps if low <= step < high])
            planned = np.concatenate([p for step, _, p, _ in beside.steps if low <= step < high])
            passive = (chosen == DO_NOTHING) & (planned != DO_NOTHING)
            print(
                f"  steps {low:>2}-{high - 1:<2}: "
                f"agrees with the planner {np.mean(chosen == planned):.2f}, "
                f"does nothing where it acts {passive.mean():.2f}, "
                f"does nothing {np.mean(chosen == DO_NOTHING):.2f} (planner "
                f"{np.mean(planned == DO_NOTHING):.2f})"
            )


if __name__ == "__main__":
    main()
