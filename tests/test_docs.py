"""The docs as a reader meets them: the README's example runs, every link and anchor
resolves, the results tables are what their data say."""

from __future__ import annotations

import importlib.util
import re
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def python_blocks(path: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.DOTALL)


def test_readme_example_runs():
    blocks = python_blocks(ROOT / "README.md")
    assert blocks, "the README has no Python example"
    for block in blocks:
        exec(compile(block, "README.md", "exec"), {})


def test_every_relative_link_in_the_docs_exists():
    for page in doc_pages():
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
            if "://" in target or target.startswith("mailto:"):
                continue
            assert (page.parent / target).exists(), f"{page.name} links to missing {target}"


@cache
def github_slug():
    """docs/hooks.py's slug function: the one the site's headings are given."""
    spec = importlib.util.spec_from_file_location("spikectl_docs_hooks", ROOT / "docs" / "hooks.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    return hooks.github_slug


FENCE = re.compile(r"^(```|~~~).*?^\1", flags=re.MULTILINE | re.DOTALL)
HEADING = re.compile(r"^#{1,6}[ \t]+(.+?)[ \t]*$", flags=re.MULTILINE)
EXPLICIT_ID = re.compile(r"\{[^}]*#([\w-]+)[^}]*\}\s*$")
HTML_ID = re.compile(r"<a\s[^>]*(?:id|name)=\"([^\"]+)\"")
ANCHORED_LINK = re.compile(r"\]\(([^)#\s]*)#([^)\s]+)\)")


def heading_text(markdown: str) -> str:
    """A heading's text as rendered (what a slug is made from): links, code spans,
    emphasis and HTML reduced to their text."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", markdown)  # [text](url) -> text
    text = re.sub(r"`([^`]*)`", r"\1", text)
    text = re.sub(r"<[^>]+>", "", text)
    text = re.sub(r"(\*{1,3})(\S.*?\S|\S)\1", r"\2", text)
    return text.replace("\\", "")


def anchors(page: Path) -> set[str]:
    """Every anchor a page has: its headings' slugs, explicit ``{#id}`` and HTML ids."""
    text = FENCE.sub("", page.read_text())
    found = set(HTML_ID.findall(text))
    for heading in HEADING.findall(text):
        explicit = EXPLICIT_ID.search(heading)
        found.add(explicit.group(1) if explicit else github_slug()(heading_text(heading)))
    return found


def every_markdown_page() -> list[Path]:
    """The README, CONTRIBUTING, CHANGELOG and every Markdown file under docs/ (the site
    builds the results folders' notes too)."""
    pages = [ROOT / "README.md", ROOT / "CONTRIBUTING.md", ROOT / "CHANGELOG.md"]
    return pages + sorted((ROOT / "docs").rglob("*.md"))


def test_github_slug_is_githubs():
    slug = github_slug()
    assert slug("Teacher-guided learning (learner.name = \"guided\")") == (
        "teacher-guided-learning-learnername--guided"
    )
    assert slug("Under the task's observation model (issue 43)") == (
        "under-the-tasks-observation-model-issue-43"
    )
    assert slug("n = 32, with CPU time") == "n--32-with-cpu-time"
    assert slug("Größe – 1 µs") == "größe--1-µs"


def test_every_anchor_in_the_docs_exists():
    """A link's #anchor names a heading of its target page, with the slug the site gives
    it (docs/hooks.py), independent of the installed Markdown libraries."""
    dead = []
    for page in every_markdown_page():
        for target, anchor in ANCHORED_LINK.findall(FENCE.sub("", page.read_text())):
            if "://" in target or (target and not target.endswith(".md")):
                continue
            linked = (page.parent / target).resolve() if target else page
            if anchor not in anchors(linked):
                dead.append(f"{page.relative_to(ROOT)} -> {target}#{anchor}")
    assert not dead, f"{len(dead)} dead anchors: {dead}"


def test_no_site_page_links_outside_the_docs_folder():
    """The site is built from docs/: a link from a page there to a file outside it
    (a source file, say) is a dead link on the site; name the file in a code span."""
    docs = ROOT / "docs"
    outside = []
    for page in sorted(docs.rglob("*.md")):
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
            if "://" in target or target.startswith("mailto:"):
                continue
            if not (page.parent / target).resolve().is_relative_to(docs):
                outside.append(f"{page.relative_to(ROOT)} -> {target}")
    assert not outside, f"links that leave docs/: {outside}"


def test_committed_results_table_is_what_its_trials_say():
    """docs/results/*/results.md is redrawn from the committed metrics, not edited by hand."""
    from spikectl.experiments.report import group_runs, load_runs, results_table
    from spikectl.experiments.sweep import trial_dirs

    sweeps = sorted(path.parent for path in (ROOT / "docs" / "results").glob("*/sweep.json"))
    assert sweeps, "no committed sweep results under docs/results/"
    for sweep_dir in sweeps:
        runs = load_runs(trial_dirs(sweep_dir))
        markdown, _ = results_table(group_runs(runs, "arch"))
        assert (sweep_dir / "results.md").read_text() == markdown, sweep_dir.name


MADE_WITH_AN_EARLIER_QUICK_PRESET = {
    "ddrqn-paper-update-ratio", "fig4-quick", "tdrqn-paper-update-ratio"
}  # fmt: skip
"""Results whose commands say ``quick`` but which ran before the preset changed
(docs/reproduction.md says so); their sweep.json reruns them exactly."""


def test_committed_sweeps_rerun_their_trials_exactly():
    """The rerun commands in the docs give the committed trials' configs: every
    sweep.json (the full description) does, and so does every sweep-file.json except
    those documented as made with an earlier quick preset."""
    import json

    from spikectl.experiments.sweep import load_sweep_file, trial_dirs
    from spikectl.training.config import Experiment

    for sweep_json in sorted((ROOT / "docs" / "results").glob("*/sweep.json")):
        folder = sweep_json.parent
        saved = {
            run.name: Experiment.from_dict(json.loads((run / "config.json").read_text()))
            for run in trial_dirs(folder)
        }
        descriptions = [sweep_json]
        if folder.name not in MADE_WITH_AN_EARLIER_QUICK_PRESET:
            descriptions.append(folder / "sweep-file.json")  # what made them
        for description in descriptions:
            # run_sweep runs every trial on one Torch thread (and records that).
            trials = {
                name: config.with_changes({"train.torch_threads": 1})
                for name, config in load_sweep_file(description).trials()
            }
            assert trials == saved, f"{description.relative_to(ROOT)} does not rerun its trials"


def test_guided_runs_script_reruns_its_trials_exactly():
    """lab/results/guided_runs.sh FOLDER SEED gives the config of every committed
    docs/results/FOLDER/trials/seed=SEED it names, with today's presets: a preset that
    changes must be pinned back in the rows made before it."""
    import json
    import shlex

    from spikectl.cli.training import parse_train
    from spikectl.training.config import Experiment

    script = (ROOT / "lab" / "results" / "guided_runs.sh").read_text()
    # The script's arrays of pinned flags (u32=(...), n100=(...)), spliced where used.
    pinned = dict(re.findall(r"^(\w+)=\((.*?)\)$", script, flags=re.MULTILINE))
    assert {"u32", "n100"} <= pinned.keys(), "guided_runs.sh's pinned flags were not read"
    commands = {}
    for folder, flags, preset in re.findall(
        r"^\s*([\w-]+)\)\s+(?:flags=\((.*?)\)|exec spikectl train (\w+))", script, re.MULTILINE
    ):
        if preset:
            commands[folder] = [preset]
        else:
            for name, value in pinned.items():
                flags = flags.replace(f'"${{{name}[@]}}"', value)
            commands[folder] = ["guided", *shlex.split(flags)]
    assert len(commands) >= 10, "guided_runs.sh's cases were not read"
    for folder, argv in commands.items():
        trials = sorted((ROOT / "docs" / "results" / folder / "trials").glob("seed=*"))
        assert trials, f"guided_runs.sh names {folder}, which has no committed trials"
        for trial in trials:
            seed = trial.name.removeprefix("seed=")
            rerun = parse_train([*argv, "--seed", seed]).config
            saved = Experiment.from_dict(json.loads((trial / "config.json").read_text()))
            assert rerun == saved, f"guided_runs.sh {folder} {seed} does not rerun {trial}"


def test_suite_train_script_reruns_its_trials_exactly():
    """lab/results/suite/train.sh TASK SEED [PRESET FOLDER FLAGS] gives the config of
    every committed run trained on a suite task: `quick` under trained/quick, the main
    job under trained/guided-upr24 with the teacher it had (the progress bar aside:
    `paper`'s quick seeds are a sweep's, which draws none)."""
    import dataclasses
    import json

    from spikectl.cli.training import parse_train
    from spikectl.training.config import Experiment

    pinned_teacher = ["--teacher-settings", "defaults"]
    for folder, preset, flags in [
        ("quick", "quick", []),
        ("guided-upr24", "guided", pinned_teacher),
    ]:
        trials = sorted((ROOT / "docs/results/suite/trained" / folder).glob("*/seed=*"))
        assert len(trials) >= 30, f"trained/{folder} has {len(trials)} runs"
        for trial in trials:
            seed, task = trial.name.removeprefix("seed="), trial.parent.name
            # On `paper` the constructor's teacher is the task's own: no flag needed.
            argv = [preset, "--task", task, "--seed", seed, *(flags if task != "paper" else [])]
            rerun = parse_train(argv).config
            saved = Experiment.from_dict(json.loads((trial / "config.json").read_text()))
            saved = dataclasses.replace(
                saved, train=dataclasses.replace(saved.train, progress=rerun.train.progress)
            )
            assert rerun == saved, f"train.sh {' '.join(argv)} does not rerun {trial}"


def doc_pages() -> list[Path]:
    """The README, CONTRIBUTING, CHANGELOG and every page of the site (docs/ and its
    folders, not the results folders' own notes)."""
    site = [page for page in sorted((ROOT / "docs").rglob("*.md"))
            if "results" not in page.relative_to(ROOT / "docs").parts]  # fmt: skip
    return [ROOT / "README.md", ROOT / "CONTRIBUTING.md", ROOT / "CHANGELOG.md", *site]


def test_the_research_index_lists_every_results_folder():
    index = (ROOT / "docs" / "research" / "index.md").read_text()
    listed = set(re.findall(r"^\| \[([\w.-]+)\]\(\.\./results/\1/\)", index, flags=re.MULTILINE))
    folders = {
        path.name
        for path in (ROOT / "docs" / "results").iterdir()
        if path.is_dir() and not path.name.startswith(("_", "."))
    }  # not __pycache__
    assert folders - listed == set(), "docs/research/index.md lacks these results folders"
    assert listed - folders == set(), "docs/research/index.md lists folders that do not exist"


def test_every_research_page_is_linked_from_the_index_and_the_site():
    """A page of dated measurements moved out of a user page is reachable: the research
    record's index links it and the site's navigation lists it."""
    research = ROOT / "docs" / "research"
    index = (research / "index.md").read_text()
    nav = (ROOT / "mkdocs.yml").read_text()
    for page in sorted(research.glob("*.md")):
        if page.name == "index.md":
            continue
        assert f"]({page.name}" in index, f"docs/research/index.md does not link {page.name}"
        assert f"research/{page.name}" in nav, f"mkdocs.yml's nav lacks research/{page.name}"


def test_readme_fits_the_first_screen():
    text = (ROOT / "README.md").read_text()
    assert len(text.split()) <= 1000
    first_block = next(i for i, line in enumerate(text.splitlines()) if line.startswith("```"))
    assert first_block < 60
    paragraphs = [p for p in text.split("\n\n") if not p.lstrip().startswith(("```", "|", "- "))]
    assert max(len(p.split()) for p in paragraphs) <= 120
    # CI's .ci/run copies the two commands: they must stay byte-identical.
    ci = (ROOT / ".ci" / "run").read_text()
    for command in re.findall(r"```bash\n(python3 -m venv[^\n]*)\n```", text):
        assert command in ci or command.endswith("spikectl train guided"), command


def test_module_paths_and_names_in_the_docs_exist():
    import importlib

    from spikectl.config_errors import MissingExtraError

    for page in doc_pages():
        text = page.read_text()
        for path in set(re.findall(r"(?<![\w/.])(spikectl/[\w/]+\.py)", text)):
            assert (ROOT / path).exists(), f"{page.name} names missing {path}"
        for dotted in set(re.findall(r"`(spikectl(?:\.\w+)+)", text)):
            parts = dotted.split(".")
            for split in range(len(parts), 0, -1):
                module = ".".join(parts[:split])
                try:
                    target = importlib.import_module(module)
                except ModuleNotFoundError:
                    continue
                except MissingExtraError:  # a module of an extra not installed here
                    if not (ROOT / (module.replace(".", "/") + ".py")).exists():
                        continue  # a name inside that module: try the module itself
                    target = None
                break
            if target is None:
                continue  # its names are checked where the extra is (its own CI venv)
            for name in parts[split:]:
                assert hasattr(target, name), f"{page.name} names missing {dotted}"
                target = getattr(target, name)


def test_the_docs_cite_nothing_outside_the_repository():
    # The project's working notes (SPEC.md, NOTES.md) are not shipped: the docs carry
    # the facts themselves.
    for page in doc_pages():
        text = page.read_text()
        for pattern in (r"\bSPEC\b", r"NOTES\.md", r"SPEC\.md", r"(?<![\w/])shared/(?!runs)"):
            assert not re.search(pattern, text), f"{page.name} cites {pattern}"


@cache
def claims_module():
    """docs/claims.py: the user pages' numbers and the committed result each comes from."""
    path = ROOT / "docs" / "claims.py"
    spec = importlib.util.spec_from_file_location("spikectl_docs_claims", path)
    claims = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(claims)
    return claims


def test_the_user_pages_state_what_their_committed_sources_say():
    """One current number per claim: each number docs/claims.py lists (the suite's table
    and leaderboard, the scores quoted on the other pages and the README) is what its
    committed CSV gives, and no page holds the claim with other numbers as well.
    `python docs/claims.py --write` copies a redrawn CSV to the pages."""
    claims = claims_module()
    assert len(list(claims.claims())) >= 40
    assert {claim.page for claim in claims.claims()} >= {
        "README.md", "docs/benchmark.md", "docs/baselines.md", "docs/training.md",
        "docs/realtime.md", "docs/getting-started.md",
    }  # fmt: skip
    assert claims.disagreements() == []


def test_a_page_that_disagrees_with_its_source_is_named_and_rewritten(tmp_path):
    claims = claims_module()
    pages = {claim.page for claim in claims.claims()}
    for page in pages:
        (tmp_path / page).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / page).write_text((ROOT / page).read_text())
    benchmark = tmp_path / "docs" / "benchmark.md"
    text = benchmark.read_text()
    # identify-and-plan's n32 cell, and a second, stale copy of the leaderboard's row
    benchmark.write_text(text.replace("| 0.725 ± 0.013 (0.483) |", "| 0.735 ± 0.013 (0.483) |")
                         + "\n| identify-and-plan | `spikectl benchmark identify-and-plan "
                         "--task all` | none | 0.649 |\n")  # fmt: skip
    wrong = claims.disagreements(tmp_path)
    assert len(wrong) == 2, wrong
    assert "0.735 ± 0.013 (0.483)" in wrong[0] and "0.725 ± 0.013 (0.483)" in wrong[0]
    assert "says '| identify-and-plan | `spikectl benchmark identify-and-plan --task all` " \
           "| none | 0.649 |'" in wrong[1]  # fmt: skip
    assert claims.write(tmp_path) == 2
    assert claims.disagreements(tmp_path) == []
    assert benchmark.read_text() == text + "\n| identify-and-plan | `spikectl benchmark " \
        "identify-and-plan --task all` | none | 0.653 |\n"  # fmt: skip
