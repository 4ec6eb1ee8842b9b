"""The research record's scripts against its committed data: a table a research page
shows is what its script prints from the committed CSVs, and the research index says
where each folder's scripts live."""

from __future__ import annotations

import re
import runpy
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LAB = ROOT / "lab" / "results"
DATA = ROOT / "docs" / "results"


def printed_rows(script: Path, capsys) -> list[str]:
    """The Markdown table rows a script prints when run as ``python SCRIPT`` (no arguments:
    pytest's own are not the script's)."""
    saved = sys.argv
    sys.argv = [str(script)]
    try:
        runpy.run_path(str(script), run_name="__main__")
    finally:
        sys.argv = saved
    return [line for line in capsys.readouterr().out.splitlines() if line.startswith("|")]


def test_benchmark_learned_tables_are_what_the_committed_csvs_say(capsys):
    """The research record's learned rows (docs/research/benchmark-suite.md) are
    learned_table.py's output, not edited by hand."""
    printed = printed_rows(LAB / "suite" / "learned_table.py", capsys)
    page = (ROOT / "docs" / "research" / "benchmark-suite.md").read_text().splitlines()
    assert len(printed) > 20
    missing = [line for line in printed if line not in page]
    assert not missing, f"benchmark-suite.md lacks {len(missing)} printed rows: {missing[:3]}"


def test_rollout_improvement_table_is_what_its_csv_says(capsys):
    printed = printed_rows(LAB / "rollout-improvement" / "table.py", capsys)
    readme = (DATA / "rollout-improvement" / "README.md").read_text().splitlines()
    assert len(printed) >= 3
    missing = [line for line in printed if line not in readme]
    assert not missing, f"rollout-improvement/README.md lacks printed rows: {missing[:3]}"


def test_the_research_index_names_where_each_folders_scripts_live():
    """docs/research/index.md's scripts column is lab/results/FOLDER/ exactly where that
    folder exists (research_index.py prints it)."""
    index = (ROOT / "docs" / "research" / "index.md").read_text()
    row = r"^\| \[([\w.-]+)\]\(\.\./results/\1/\) \|.*\| (`lab/results/[\w.-]+/`|none) \| [\d-]+ \|"
    rows = re.findall(row, index, flags=re.MULTILINE)
    assert len(rows) >= 60, "the index's rows were not read"
    for folder, scripts in rows:
        expected = f"`lab/results/{folder}/`" if (LAB / folder).is_dir() else "none"
        assert scripts == expected, f"index row {folder}: {scripts}, expected {expected}"


def test_reference_baselines_table_is_what_the_committed_runs_say(capsys):
    """docs/results/reference-baselines/README.md's table is table.py's output from the
    committed runs (result.json, per-network CSVs), not edited by hand."""
    printed = printed_rows(LAB / "reference-baselines" / "table.py", capsys)
    readme = (DATA / "reference-baselines" / "README.md").read_text().splitlines()
    assert len(printed) >= 7  # header, rule and five algorithms
    missing = [line for line in printed if line not in readme]
    assert not missing, f"reference-baselines/README.md lacks printed rows: {missing[:3]}"


def test_realtime_tradeoff_table_is_what_the_committed_rows_say(capsys):
    """docs/results/realtime-tradeoff/README.md's tables are table.py's output from the
    committed rows (the suite's, the amortised controller's and the folder's own)."""
    printed = printed_rows(LAB / "realtime-tradeoff" / "table.py", capsys)
    readme = (DATA / "realtime-tradeoff" / "README.md").read_text().splitlines()
    assert len(printed) >= 2 + 4 * 6  # header, rule and at least six controllers a size
    missing = [line for line in printed if line not in readme]
    assert not missing, f"realtime-tradeoff/README.md lacks printed rows: {missing[:3]}"


def test_decision_times_fill_only_the_two_columns(tmp_path):
    """lab/results/suite/decision_times.py on a CSV written before the columns existed:
    a registered controller's row and a run's row (timed with the architecture of the
    config.json beside it) gain positive p50 <= p99; nothing else changes."""
    import csv
    import shutil

    script = runpy.run_path(str(LAB / "suite" / "decision_times.py"))
    run = DATA / "suite" / "trained" / "guided-upr24" / "noise2" / "seed=0"
    shutil.copy(run / "config.json", tmp_path / "config.json")
    fields = ["suite_version", "task", "split", "controller", "model", "mean_return"]
    rows = [["1", "noise2", "test", "runs/gone/seed=0", "best", "0.7"],
            ["1", "paper", "test", "do-nothing", "", "0.5"]]  # fmt: skip
    path = tmp_path / "benchmark.csv"
    with path.open("w", newline="") as handle:
        csv.writer(handle).writerows([fields, *rows])
    written = script["timed_rows"](path, 1)
    assert [[row[field] for field in fields] for row in written] == rows
    for row in written:
        assert 0 < float(row["decision_p50_ms"]) <= float(row["decision_p99_ms"])


def test_column_belief_tables_are_what_the_committed_rows_say():
    """docs/results/column-belief/README.md's tables are measure.py's ``table`` from the
    committed rows (its own, the suite's and the amortised controller's)."""
    table = runpy.run_path(str(LAB / "column-belief" / "measure.py"))["table"]
    printed = [line for line in table(DATA / "column-belief").splitlines() if line.startswith("|")]
    readme = (DATA / "column-belief" / "README.md").read_text().splitlines()
    assert len(printed) == 2 + 6 + 2 + 3
    missing = [line for line in printed if line not in readme]
    assert not missing, f"column-belief/README.md lacks printed rows: {missing[:3]}"


def test_suite_v2_learned_table_is_what_the_committed_runs_say(capsys):
    """docs/results/suite-v2/README.md's learned rows through the latency loop are
    learned_table.py's output from the committed per-network CSVs."""
    printed = printed_rows(LAB / "suite-v2" / "learned_table.py", capsys)
    readme = (DATA / "suite-v2" / "README.md").read_text().splitlines()
    assert len(printed) >= 2 + 2  # header, rule, latency1 and latency2
    missing = [line for line in printed if line not in readme]
    assert not missing, f"suite-v2/README.md lacks printed rows: {missing[:3]}"


def test_suite_v2_paired_presets_are_what_the_committed_runs_say():
    """The suite-v2 record's two presets against each other (with and without the
    actions-in-flight input) are learned_table.py --paired's output."""
    script = runpy.run_path(str(LAB / "suite-v2" / "learned_table.py"))
    printed = [line for line in script["paired"]("guided-in-flight", "guided").splitlines()
               if line.startswith("|")]  # fmt: skip
    readme = (DATA / "suite-v2" / "README.md").read_text().splitlines()
    assert len(printed) == 3  # header, rule, latency2
    missing = [line for line in printed if line not in readme]
    assert not missing, f"suite-v2/README.md lacks printed rows: {missing[:3]}"
