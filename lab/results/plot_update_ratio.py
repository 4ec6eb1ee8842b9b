"""Redraw the update-ratio comparison of docs/reproduction.md from committed results.

    python lab/results/plot_update_ratio.py docs/results docs/images/update_ratio.png
"""

import sys
from pathlib import Path

from spikectl.experiments.report import plot_training_curves, results_table
from spikectl.experiments.sweep import trial_dirs

results = Path(sys.argv[1])
fig4 = trial_dirs(results / "fig4-quick")
groups = {
    "TDRQN, 0.625 updates/episode": [d for d in fig4 if d.name.startswith("arch=tdrqn")],
    "TDRQN, 2 updates/episode": trial_dirs(results / "tdrqn-paper-update-ratio"),
    "DDRQN, 0.625 updates/episode": [d for d in fig4 if d.name.startswith("arch=ddrqn")],
    "DDRQN, 2 updates/episode": trial_dirs(results / "ddrqn-paper-update-ratio"),
}
plot_training_curves(groups, sys.argv[2])
print(results_table(groups)[0])
