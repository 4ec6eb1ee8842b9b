"""The candidate chosen on ``n16``'s train and validation sets (``ConfoundedZeros`` with
sd 0.2, validation.py), played once on the ``n16`` test set: writes
``test-n16-per-network.csv`` in the format of ``spikectl benchmark --per-network``.

    python docs/results/confounded-zeros/test.py docs/results/confounded-zeros
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

from validation import ConfoundedZeros

from spikectl.experiments import suite
from spikectl.planning.policy import environment_settings

CHOSEN_SD = 0.2


def main(out: Path) -> None:
    spec = suite.task("n16")
    controller = ConfoundedZeros(CHOSEN_SD, **environment_settings(spec.extensions, 16))
    returns, seconds = suite.play("n16", "test", controller)
    with open(out / "test-n16-per-network.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["suite_version", "task", "split", "controller", "model", "context",
                         "return"])  # fmt: skip
        for index, value in enumerate(returns):
            writer.writerow([suite.suite_version(1).number, "n16", "test", "identify-and-plan", "",
                             index, repr(float(value))])  # fmt: skip
    print(f"n16 test: {returns.mean():.6f} ({seconds:.0f} CPU s)")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
