"""Play an ADVISOR run's best model on the suite's `paper` test networks, network by
network, as ``spikectl benchmark RUN --model best --task paper --per-network OUT`` does
for a library learner (the command refuses a config naming ``guided-advisor`` until the
learner is registered, which this script does first).

    python lab/results/advisor/benchmark.py RUN_DIR OUT_CSV
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from advisor import AdvisorConfig, AdvisorLearner, register  # noqa: E402

from spikectl.cli import main  # noqa: E402

if __name__ == "__main__":
    run_dir, out = sys.argv[1:3]
    register(AdvisorConfig, AdvisorLearner)
    main(["benchmark", run_dir, "--model", "best", "--task", "paper", "--per-network", out])
