"""Draw the figure of docs/baselines.md from the committed per-context CSVs.

    python docs/results/baselines/plot_baselines.py docs/results/baselines \
        docs/images/baselines.png
"""

import csv
import sys
from pathlib import Path

import numpy as np

SETTINGS = {  # CSV stem -> label
    "test_n8": "n = 8\n(the paper)",
    "test_noisy2": "n = 8, noise\n2 mV",
    "test_partial": "n = 8, 2 of 8\nhidden",
    "test_n32": "n = 32",
}
CONTROLLERS = ("do_nothing", "random", "identify_and_plan", "oracle", "witness")


def plot(results: Path, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    present = [stem for stem in SETTINGS if (results / f"{stem}.csv").exists()]
    figure, axis = plt.subplots(figsize=(8, 3.6))
    width = 0.8 / len(CONTROLLERS)
    for k, name in enumerate(CONTROLLERS):
        means, errors = [], []
        for stem in present:
            with (results / f"{stem}.csv").open() as handle:
                values = np.array([float(row[name]) for row in csv.DictReader(handle)])
            means.append(values.mean())
            errors.append(values.std(ddof=1) / np.sqrt(values.size))
        positions = np.arange(len(present)) + (k - (len(CONTROLLERS) - 1) / 2) * width
        axis.bar(positions, means, width, yerr=errors, label=name.replace("_", "-"))
    axis.set_xticks(np.arange(len(present)), [SETTINGS[stem] for stem in present])
    axis.set_ylim(0.4, 1.02)
    axis.set_ylabel("mean return, 100 unseen networks")
    axis.axhline(0.5, color="grey", linewidth=0.5)
    axis.legend(ncol=5, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, 1.15))
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=120)
    print(f"wrote {out}")


if __name__ == "__main__":
    plot(Path(sys.argv[1]), Path(sys.argv[2]))
