"""Write docs/research/index.md's table of every results folder from what the folder
holds and the git log: its claim (the subject of the commit that added it), the command
that reruns it, the day it was added and the CPU its runs recorded.

    python lab/results/research_index.py > /tmp/table.md   # then paste into the index

Run from the repository root of a full clone (the dates and claims come from git).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

LAB_RESULTS = Path(__file__).resolve().parent
"""The scripts of the research record (lab/results/FOLDER/ beside each data folder)."""
ROOT = LAB_RESULTS.parent.parent
RESULTS = ROOT / "docs" / "results"
"""The committed data: configs, metrics, CSVs, figures (docs/results/FOLDER/)."""
CLAIM_CHARS = 220
# Folders whose first commits' subjects name something else (a folder committed beside
# another change): their claim as the commit that reported the result stated it.
CLAIMS = {
    "realtime-iap": "identify-and-plan-realtime (the fast form at beam width 12) ties the "
    "named identify-and-plan on the paper / n16 test sets (+0.001 / +0.002 per network) at "
    "CPU p99 0.69 / 0.90 ms; at n32 2.0 ms and -0.031; a beam cut to the target's ancestors "
    "saved no time",
    "column-belief": "the amortised controller fed identify-and-plan's exact Gaussian "
    "posterior of the target's column scores what it scores on the trained belief at n16 "
    "/ n32 (-0.001 / -0.008 per network) and stays below identify-and-plan (test -0.041 / "
    "-0.057): the limit is the one-column rule, not the belief",
    "realtime-tradeoff": "return against decision CPU time for every controller at n = 8, 16, "
    "32 and 64 (one timing run, nothing else running): identify-and-plan's fast form ties "
    "the named one at n16 (-0.001 [-0.029, +0.027]) at p99 1.7 ms against 181 ms; within "
    "1 ms the amortised controller",
    "iap-spikes": "identify-and-plan from spikes alone (suite v2 spikes-only): the loss is "
    "identification, almost all of it the target's column (told it +0.204 on 200 validation "
    "networks); QMDP where it would probe chosen on 600 (+0.013, +0.016), test 0.765 -> "
    "0.778 (+0.013 [+0.009, +0.018])",
    "iap-rig": "identify-and-plan plays suite v2's rig (refused before) with a spike "
    "likelihood, each light sequence planned over 8 networks drawn from it: test 0.617 -> "
    "0.691 (+0.074 [+0.066, +0.082]), short of 0.70; told the true columns 0.869 vs 0.606",
    "iap-chr2": "identify-and-plan under ChR2 light (suite v2 chr2): the loss is in "
    "identification (told the weights +0.159 on 50 validation networks); the exact "
    "posterior chosen on 400 validation networks (+0.020 [+0.009, +0.032]), test 0.740 -> "
    "0.761 (+0.021 [+0.013, +0.029])",
    "chr2-learners": "the guided preset on suite v2's chr2 and rig stays near doing nothing "
    "(validation <= 0.551, seven variants): its student learns when to light, not which neuron; "
    "its teachers light the target's inputs 35 % of the time",
    "amortised-belief": "an amortised belief over the target's inputs (neurons as tokens, "
    "trained 18 CPU-minutes on generated episodes, sizes 8-32): at n = 32 it removes 51 % "
    "of the base rate's cross-entropy after 50 steps (identify-and-plan's Gaussian estimate "
    "74 %); at n = 8 within 8 % of the exact posterior's NLL over the episode",
    "cleo-agreement": "controllers made for each loop (latency, ChR2, spikes only, the rig "
    "without background) in Cleo and in spikectl with the matching extensions: every "
    "action and return equal, 100 networks per setting and controller",
    "belief-policy": "a policy on the amortised belief (DAgger on identify-and-plan, then "
    "REINFORCE): test 0.830 / 0.737 / 0.640 on paper / n16 / n32, -0.007 [-0.033, +0.020] "
    "against identify-and-plan at n = 8 (p99 0.67 ms), below the fixed rule at 16 and 32; "
    "REINFORCE changed no greedy action",
    "amortised-controller": "a controller on the amortised belief (greedy on P(input), "
    "probes on quiet stretches; compiled step, CPU p99 0.6-1.2 ms at n = 16-32 on the "
    "loaded machine): test 0.806 / 0.742 / 0.675 on paper / n16 / n32, -0.032 / -0.041 / "
    "-0.049 against identify-and-plan, all below 0; told the target's column the same "
    "rule scores 0.916 / 0.841 / 0.808: the gap is identification",
    "reliability": "the measurements behind docs/reliability.md: round 4's probes (all "
    "ok); Ctrl-C while Python starts and while Numba compiles (32/40 clean before the fix, "
    "40/40 after); round 3's CPU-kind numbers; tolerances",
    "exact-filter": "identify-and-plan's filter trusts the paper's deterministic step under "
    "measurement noise: told the weights 0.949 -> 0.993 (validation); named controller "
    "+0.014 [+0.005, +0.024] on the validation sets, +0.019 [+0.008, +0.030] on the test "
    "sets (noise1 0.803, noise2 0.795, noise4 0.769); suite mean 0.593 -> 0.605",
    "heterogeneous-neurons": "identify-and-plan learns each neuron's threshold and leak and "
    "plans known synapses at their strength: heterogeneous validation 0.769 -> 0.855 "
    "(+0.086 [+0.051, +0.121]), test 0.768 -> 0.869 (+0.101 [+0.073, +0.129]); suite mean "
    "0.605 -> 0.626",
    "release-settling": "identify-and-plan settles stochastic releases from the next "
    "step's residuals: known weights right 0.879 -> 0.997; stochastic train + validation "
    "0.675 -> 0.688 (+0.013 [+0.002, +0.025]), test 0.670 -> 0.678 (+0.007 [-0.014, "
    "+0.028], within noise); suite mean 0.626 -> 0.629",
    "filter-margin": "under measurement noise identify-and-plan plans spikes within its "
    "filter's read margin of the threshold: noise tasks' train + validation +0.030 / +0.029 / "
    "+0.030, test 0.803 / 0.795 / 0.769 -> 0.827 / 0.815 / 0.796 (+0.024 [+0.016, +0.032] "
    "pooled); suite mean 0.629 -> 0.643",
    "unrested-inputs": "under stochastic release identify-and-plan stimulates a known input "
    "at its release chance where its plan misses the next wanted spike: train + validation "
    "+0.008 [+0.002, +0.014], test 0.678 -> 0.686 (+0.008 [+0.001, +0.016]); suite mean "
    "0.643 -> 0.646",
    "hidden-relays": "with hidden neurons identify-and-plan learns each observed neuron's "
    "effect two steps after its release and plans it through virtual relay neurons: train + "
    "validation +0.022 [+0.006, +0.038], hidden25 test 0.814 -> 0.831 (+0.017 [-0.003, "
    "+0.037]); suite mean 0.646 -> 0.649",
    "proximity-input": "the guided learner with the generator's prior of a synapse onto the "
    "target at each neuron's distance as an input: n = 8 (3 seeds) within noise, validation "
    "0.839 vs 0.834, test 0.813 vs 0.809; n16 (3 seeds) faster, within noise at the end, test "
    "0.695 vs 0.686; n32 (3 seeds) best validation 0.571 vs 0.555, test 0.572 vs 0.535",
    "advisor": "ADVISOR on the guided learner (imitation weighted per step by how well an "
    "imitation-only head matches the teacher): with identify-and-plan, 3 seeds, validation "
    "0.814 vs 0.834 for the main job, test 0.807 vs 0.809, -0.031 [-0.055, -0.009] vs the "
    "planner; with the teacher told the weights 0.781 vs 0.733 (pilot, an older preset); "
    "not adopted",
    "asymmetric-critic": "the main job with a privileged critic that reads the target's true "
    "inputs (asymmetric DQN): validation 0.828 vs 0.832 at the end, test 0.816 vs 0.810 (3 "
    "seeds each), -0.021 [-0.048, +0.005] vs identify-and-plan; no change",
    "task-teacher": "the guided learner's teacher on the task's own settings (identify-and-plan "
    "with the extensions on heterogeneous, 0.869 test against 0.768): validation 0.768 vs "
    "0.767 (3 seeds each), test 0.767 vs 0.777, 0.10 below its teacher; n16 (3 seeds) "
    "0.712 vs 0.707",
    "particles": "identify-and-plan's discrete posterior at 16 and 32 neurons kept by "
    "particles: within noise of the Gaussian estimate in its tuned forms; taken by the named "
    "controller at 32 on validation (+0.022 [+0.002, +0.041]), test -0.015 [-0.042, +0.013]",
    "rollout-improvement": "where identify-and-plan would probe, each candidate valued by "
    "playing the controller itself on networks drawn from its estimate (rollout policy "
    "improvement): paper train + validation -0.010 [-0.025, +0.003] at about 300x the CPU "
    "time; not kept",
    "confounded-zeros": "what a probe teaches about the target's column (about half of the early "
    "probes are lost to the target's refractory step or another release), and a column that "
    "did not move while several neurons released counted as no synapse from each: n16 train + "
    "validation +0.010 [-0.000, +0.020], n32 validation -0.008, n16 test +0.000; not kept",
    "probing-rules": "identify-and-plan's probing rule against three others (probe also when "
    "idle and no spike is near, only when a missed spike is near, candidates ranked by "
    "Dale's law): none better on paper train / validation or n16 validation (-0.000 to "
    "-0.067)",
    "reachable": "what better identification could buy at n = 8 (validation): identify-and-"
    "plan 0.694 normalised over seven tasks, told the target's inputs from step 5 0.792, "
    "from step 1 0.845, told every weight 0.968",
    "first-action": "identify-and-plan's first action chosen from the target and the pattern "
    "(12 000 generator contexts, every legal first action played): +0.002 +- 0.002 on "
    "held-out contexts, nothing to gain at step 0; a 16-network look-ahead at step 0 "
    "scores 0.848 against 0.866 (validation)",
    "advice-input": "identify-and-plan's next action as the student's input (3 seeds, "
    "validation): the guided learner becomes the planner (0.866, every step advised, every "
    "n = 8 suite task network by network); by reward alone it leaves the planner for the "
    "worse (0.866 -> 0.802)",
    "belief-input": "identify-and-plan's belief about the target's inputs as the student's "
    "input (3 seeds, validation): no change on the paper's task (-0.000 [-0.014, +0.014]), "
    "+0.018 [-0.008, +0.043] played at n32, +0.035 [+0.016, +0.053] on heterogeneous "
    "neurons; fine-tuned at 32 it follows its teacher more (0.50-0.53 against 0.35-0.37) "
    "but never beats its zero-shot start",
    "bayes-identify": "identify-and-plan's Bayes observation models chosen on validation and "
    "played once on the suite's test sets: stochastic 0.505 -> 0.618 normalised, noise tasks "
    "unchanged within noise, suite mean 0.557 -> 0.567; then QMDP from 16 neurons on: n16 "
    "0.744 -> 0.780, n32 0.676 -> 0.712, suite mean 0.582; then known_sd chosen per size "
    "and condition: n32 0.712 -> 0.735 (0.506 normalised), suite mean 0.593",
    "cleo-sim-to-sim": "identify-and-plan, the oracle and three trained TDRQN seeds in "
    "Cleo/Brian 2: ideal setting = spikectl on 100 test networks (0 of 500 episodes differ); "
    "one step of latency or ChR2 puts all at or near doing nothing; 1 mV noise costs TDRQN "
    "0.007, identify-and-plan 0.135",
    "curriculum-n32-pilot": "The main job's n = 8 network fine-tuned at n = 32 with its "
    "teacher (1 seed, 25 core-minutes): never above its zero-shot start (0.622 test); teacher "
    "agreement stays 0.35-0.37",
    "curriculum": "A curriculum over sizes (3 seeds): the n = 8 main job with the proximity "
    "input fine-tuned on n16, then n32: within noise of the n = 8 network played zero-shot "
    "(+0.005 [-0.009, +0.018], +0.005 [-0.012, +0.024]), above training from scratch (+0.030, "
    "+0.059), below identify-and-plan (-0.057, -0.105)",
    "student-n32-diagnosis": "Why the student does not follow its teacher at 32 neurons "
    "(validation): it does not identify the target's inputs (16-26% of its stimulations where "
    "the planner plans are true inputs, against 57-59%); the distance prior is worth -0.015 "
    "[-0.050, +0.022] to the planner itself",
    "ddrqn-paper-update-ratio": "DDRQN at the paper's update ratio finished (1 M steps, 1 seed): "
    "0.654 train / 0.621 unseen, below TDRQN's 0.833 / 0.800",
    "tdrqn-paper-update-ratio": "TDRQN with the paper's 2 updates per episode reaches 0.833 train "
    "/ 0.800 unseen (2 seeds)",
    "learn-fast-without-aux-loss": "Ablation of the quick preset without the auxiliary "
    "next-voltage loss (3 seeds; docs/research/training-experiments.md, Ablation)",
    "learn-fast-without-target-voltage": "Ablation of the quick preset without the target-voltage "
    "input (3 seeds; docs/research/training-experiments.md, Ablation)",
    "guided-ntrain4000-4x": "4x the steps on 4 000 networks, 3 seeds: validation 0.839 ± 0.003, "
    "unseen 0.818 ± 0.002 in 42-44 core-minutes, the same plateau",
    "quick-this-machine": "The quick preset rerun on the project's machine, 3 seeds: unseen "
    "0.743 ± 0.016 final, 0.741 ± 0.003 selected on validation",
    "paper-protocol": "The paper's protocol at Table 2 on one H100, partial: every seed still "
    "near 0.5 when the session ended; the pace, not results",
}


def git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                          check=True).stdout.strip()  # fmt: skip


def first_commit(folder: Path) -> tuple[str, str]:
    """(date, subject): the day the folder was added, and the subject of the earliest
    commit touching it that names it (else that says "result", else the earliest)."""
    log = git("log", "--format=%ad%x09%s", "--date=short", "--", str(folder.relative_to(ROOT)))
    commits = [line.split("\t", 1) for line in reversed(log.splitlines())]
    for test in (lambda s: folder.name in s, lambda s: "result" in s.lower(), lambda s: True):
        chosen = [subject for _, subject in commits if test(subject)]
        if chosen:
            return commits[0][0], chosen[0]
    raise AssertionError(f"no commit touches {folder}")


def command(folder: Path) -> str:
    name = folder.name
    if (folder / "sweep-file.json").exists():
        return (f"`spikectl sweep --config docs/results/{name}/sweep-file.json "
                f"--sweep-dir runs/{name}`")  # fmt: skip
    if (folder / "sweep.json").exists():
        return f"`spikectl sweep --config docs/results/{name}/sweep.json --sweep-dir runs/{name}`"
    runs_script = (LAB_RESULTS / "guided_runs.sh").read_text()
    if f"    {name})" in runs_script:
        return f"`bash lab/results/guided_runs.sh {name} SEED`"
    if (folder / "README.md").exists():
        return f"in [its README](../results/{name}/README.md)"
    if (LAB_RESULTS / name / "train.sh").exists():
        return f"`bash lab/results/{name}/train.sh TASK SEED`"
    return "in the page that cites it"


def cpus(folder: Path) -> str:
    """The CPU kinds the folder's runs recorded (machine.json), or where they are not."""
    kinds = set()
    for machine in folder.rglob("machine.json"):
        for start in json.loads(machine.read_text()).get("starts", []):
            avx = "AVX-512" if start.get("avx512f") else "AVX2" if start.get("avx2") else "?"
            kinds.add(f"{start.get('cpu', '?')} ({avx})")
    lscpu = folder / "lscpu.txt"
    if not kinds and lscpu.exists():
        for line in lscpu.read_text().splitlines():
            if line.startswith("Model name:"):
                kinds.add(line.split(":", 1)[1].strip())
    return ", ".join(sorted(kinds)) or "not recorded"


def scripts(folder: Path) -> str:
    """Where the folder's scripts live: lab/results/FOLDER/, or none."""
    lab = LAB_RESULTS / folder.name
    return f"`lab/results/{folder.name}/`" if lab.is_dir() else "none"


def seeds(folder: Path) -> int:
    return len(list(folder.glob("trials/*seed=*"))) + len(list(folder.glob("trials/seed=*")))


def main() -> None:
    print("| folder | claim (from the commit that added it) | command | scripts | added | CPU |")
    print("|---|---|---|---|---|---|")
    for folder in sorted(path for path in RESULTS.iterdir() if path.is_dir()):
        if folder.name.startswith(("_", ".")):
            continue
        date, subject = first_commit(folder)
        subject = CLAIMS.get(folder.name, subject)
        claim = subject if len(subject) <= CLAIM_CHARS else subject[:CLAIM_CHARS] + " …"
        claim = claim.replace("|", "/")
        print(f"| [{folder.name}](../results/{folder.name}/) | {claim} | {command(folder)} "
              f"| {scripts(folder)} | {date} | {cpus(folder)} |")  # fmt: skip


if __name__ == "__main__":
    main()
