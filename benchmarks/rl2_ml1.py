"""RL² on Meta-World ML1 (goal hidden): meta-train and meta-test success vs env steps over
several seeds, and the adaptation curve (success at episode 1..K of a trial on held-out goals)
of RL² next to a memoryless PPO baseline.

    python benchmarks/rl2_ml1.py [--variants NAME ...]   (every name in VARIANTS below; --help lists them)
                                 [--seeds 0 1 2] [--steps 2000000] [--chunk-steps 500000] [--trials 50]

The full budget takes many hours on 2 cores, so the script works in chunks (like
pick_place_curriculum.py): each call advances every run by at most `--chunk-steps`, resuming
from its checkpoint, then evaluates the checkpoint on `--trials` trials of the ML1 train goals
(meta-train) and of the 50 held-out goals (meta-test), each trial K episodes from a fresh
hidden state (K the agent's `rl2.trial_episodes`, 5 for every shipped variant but
rl2-reach-mwplus's and rl2-pick-place-mwplus's 10, Meta-World+'s; the PPO baseline
plays trials of 5; it cannot adapt, so its curve is flat),
once acting with the policy's mean and once sampling from it (as Duan et al.'s meta-test; an RL²
policy's first-episode search may live in its sampling noise). A finished run given again gets
any evaluation it lacks. Evaluations are kept in each run's `meta_evals.jsonl`; the table and
JSON are rebuilt from them, so run it again to continue.

Reference: the Meta-World paper (Yu et al., CoRL 2019; arXiv 1910.10897) reports ML1 only as
learning curves, not a table: arXiv v2 Figure 4 ("Comparison on our simplest meta-RL
evaluation, ML1") and appendix Figures 12-14 (RL², MAML, PEARL on ML1 reach, push, pick-place),
CoRL version Figure 7. Their RL² ran Meta-World v1 with 500-step paths, 10 roll-outs per task,
a 256-unit GRU and PPO (appendix Table 10), for far more env steps than fit here.
"""

from __future__ import annotations

import itertools
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS, advance_run, chunked_parser, print_table, pyplot, save_figure, write_result  # noqa: E402
from taskforge.evaluation.report import evaluate_run  # noqa: E402
from taskforge.run import RunDir, load_checkpoint, policy_file, read_jsonl, save_checkpoint  # noqa: E402
from taskforge.spec import SpecError, init_for_seed, resolve_relative  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = {
    "rl2-reach": ROOT / "curricula/ml1_reach_rl2.yaml",
    "rl2-reach-whole-trial": ROOT / "benchmarks/configs/ml1_reach_rl2_whole_trial.yaml",
    "rl2-reach-explore": ROOT / "benchmarks/configs/ml1_reach_rl2_explore.yaml",
    "rl2-reach-short": ROOT / "benchmarks/configs/ml1_reach_rl2_short.yaml",
    "rl2-reach-native": ROOT / "benchmarks/configs/ml1_reach_rl2_native.yaml",
    "rl2-reach-mwplus": ROOT / "benchmarks/configs/ml1_reach_rl2_mwplus.yaml",
    "ppo-reach-mwplus": ROOT / "benchmarks/configs/ml1_reach_ppo_mwplus.yaml",
    "rl2-reach-sparse": ROOT / "benchmarks/configs/ml1_reach_rl2_sparse.yaml",
    "rl2-reach-linear": ROOT / "benchmarks/configs/ml1_reach_rl2_linear.yaml",
    "rl2-reach-progress": ROOT / "benchmarks/configs/ml1_reach_rl2_progress.yaml",
    "rl2-reach-plane": ROOT / "benchmarks/configs/ml1_reach_rl2_plane.yaml",
    "rl2-reach-found": ROOT / "benchmarks/configs/ml1_reach_rl2_found.yaml",
    "rl2-reach-found-explore": ROOT / "benchmarks/configs/ml1_reach_rl2_found_explore.yaml",
    "rl2-reach-found-short": ROOT / "benchmarks/configs/ml1_reach_rl2_found_short.yaml",
    "rl2-reach-found-calm": ROOT / "benchmarks/configs/ml1_reach_rl2_found_calm.yaml",
    "rl2-reach-found-hand": ROOT / "benchmarks/configs/ml1_reach_rl2_found_hand.yaml",
    "rl2-reach-box-hand": ROOT / "benchmarks/configs/ml1_reach_rl2_box_hand.yaml",
    "rl2-reach-zone": ROOT / "benchmarks/configs/ml1_reach_rl2_zone.yaml",
    "rl2-reach-zone-find": ROOT / "benchmarks/configs/ml1_reach_rl2_zone_find.yaml",
    "rl2-reach-zone-find-calm": ROOT / "benchmarks/configs/ml1_reach_rl2_zone_find_calm.yaml",
    "rl2-reach-zone-find-mid": ROOT / "benchmarks/configs/ml1_reach_rl2_zone_find_mid.yaml",
    "rl2-reach-zone-find-deep": ROOT / "benchmarks/configs/ml1_reach_rl2_zone_find_deep.yaml",
    "rl2-reach-zone-find-more": ROOT / "benchmarks/configs/ml1_reach_rl2_zone_find_more.yaml",
    "rl2-reach-zone-find-short": ROOT / "benchmarks/configs/ml1_reach_rl2_zone_find_short.yaml",
    "rl2-reach-zone-plane": ROOT / "benchmarks/configs/ml1_reach_rl2_zone_plane.yaml",
    "rl2-reach-zone-grow": ROOT / "benchmarks/configs/ml1_reach_rl2_zone_grow.yaml",
    "rl2-reach-zone-box-from-plane": ROOT / "benchmarks/configs/ml1_reach_rl2_zone_box_from_plane.yaml",
    "rl2-reach-zone-box-from-plane-long": ROOT / "benchmarks/configs/ml1_reach_rl2_zone_box_from_plane_long.yaml",
    "ppo-reach-zone-find": ROOT / "benchmarks/configs/ml1_reach_ppo_zone_find.yaml",
    "ppo-reach-zone-plane": ROOT / "benchmarks/configs/ml1_reach_ppo_zone_plane.yaml",
    "ppo-reach": ROOT / "benchmarks/configs/ml1_reach_ppo.yaml",
    "rl2-push": ROOT / "benchmarks/configs/ml1_push_rl2.yaml",
    "ppo-push": ROOT / "benchmarks/configs/ml1_push_ppo.yaml",
    "rl2-push-hand": ROOT / "benchmarks/configs/ml1_push_rl2_hand.yaml",
    "ppo-push-hand": ROOT / "benchmarks/configs/ml1_push_ppo_hand.yaml",
    "rl2-push-hold": ROOT / "benchmarks/configs/ml1_push_rl2_hold.yaml",
    "ppo-push-hold": ROOT / "benchmarks/configs/ml1_push_ppo_hold.yaml",
    "rl2-push-zone-find": ROOT / "benchmarks/configs/ml1_push_rl2_zone_find.yaml",
    "ppo-push-zone-find": ROOT / "benchmarks/configs/ml1_push_ppo_zone_find.yaml",
    "rl2-push-zone-find-short": ROOT / "benchmarks/configs/ml1_push_rl2_zone_find_short.yaml",
    "ppo-push-zone-find-short": ROOT / "benchmarks/configs/ml1_push_ppo_zone_find_short.yaml",
    "rl2-pick-place": ROOT / "benchmarks/configs/ml1_pick_place_rl2.yaml",
    "rl2-pick-place-mwplus": ROOT / "benchmarks/configs/ml1_pick_place_rl2_mwplus.yaml",
}
RUNS = ROOT / "benchmarks/runs/rl2"
TRIAL_EPISODES = 5  # agents/rl2.yaml's K; a PPO baseline is evaluated over trials of this many episodes


def meta_evaluate(
    run_dir: Path, step: int, trials: int, sampled: bool, trial_episodes: int | None = None,
    splits: tuple[str, ...] = ("train", "test"), checkpoint: Path | None = None,
) -> list[dict]:
    """Meta-train and meta-test evaluation (`splits`) of the run's checkpoint at `step`, cached per step.

    `sampled`: act by sampling from the policy instead of taking its mean. An RL² policy's
    exploration in a trial's first episodes is its sampling noise as much as its mean (Duan et
    al. and garage meta-test with sampled actions), so the mean alone may hide adaptation.
    Cache entries written before this option had no `sampled` key: they are mean-action ones.
    The stage evaluated is the one the run's curriculum evaluates (`evaluation.stage`, read from
    the run's config.json: e.g. the last of a curriculum of stages), else the run's first, the
    only one of a one-stage curriculum. A trial has `trial_episodes` episodes, by default the
    run's own K (`rl2.trial_episodes` of its agent; TRIAL_EPISODES for a memoryless baseline).
    `checkpoint`: another file to play as the run's step `step` (`starting_point`)."""
    run = RunDir(run_dir)
    config = json.loads(run.config.read_text())
    stage = config["curriculum"]["evaluation"]["stage"]
    if trial_episodes is None:
        trial_episodes = config["agent"]["rl2"]["trial_episodes"] if config["agent"]["algo"] == "rl2" else TRIAL_EPISODES
    cache = run_dir / "meta_evals.jsonl"
    done = [e for e in read_jsonl(cache) if e["step"] == step and e["trials"] == trials and e.get("sampled", False) == sampled]
    for split in splits:
        if any(e["split"] == split for e in done):
            continue
        report = evaluate_run(checkpoint or run.checkpoint, split=split, trials=trials, trial_episodes=trial_episodes,
                              deterministic=not sampled, stages=[stage] if stage else None)
        row = report["rows"][0]
        entry = {"step": step, "split": split, "trials": trials, "sampled": sampled, "success_rate": row["success_rate"],
                 "per_episode": [e["success_rate"] for e in row["per_episode"]],
                 "per_episode_return": [e["mean_return"] for e in row["per_episode"]],
                 "per_episode_length": [e["mean_length"] for e in row["per_episode"]],
                 "after_first_episode": row.get("after_first_episode")}
        with cache.open("a") as f:
            f.write(json.dumps(entry) + "\n")
        done.append(entry)
    return done


def evaluate_starting_point(run_dir: Path, trials: int) -> None:
    """An `init_from` run's step 0, meta-evaluated as every later checkpoint is: the weights it
    started from, saved with the run's own config (so they play its task and stage) in a
    temporary file. Why: the run's own evaluation before its first update has 10 trials; the
    comparison with what the run made of them needs the same 50. Nothing for a run started from
    scratch, or whose source has no policy on this machine (final policies are not committed)."""
    config = json.loads(RunDir(run_dir).config.read_text())
    source = config["curriculum"].get("init_from")
    if source is None:
        return
    try:
        state = load_checkpoint(policy_file(resolve_relative(config["curriculum_file"], init_for_seed(source, config["seed"]))))
    except SpecError:
        return
    with tempfile.TemporaryDirectory() as folder:
        start = Path(folder) / "start.pt"
        save_checkpoint({"config": config, "agent": state["agent"], "curriculum": {}}, start)
        for sampled in (False, True):
            meta_evaluate(run_dir, 0, trials, sampled, checkpoint=start)


SPLITS = ("train", "test", "train_sampled", "test_sampled")  # mean-action and sampled-action evaluations


SAME_POINT = 0.1  # evaluations of sibling seeds within 10 % (+ 20k steps) of each other count as one point


def evaluation_points(seeds: list[dict]) -> list[dict]:
    """The evaluations of every seed of one variant, grouped into points of (about) the same step.

    Why not exact steps: chunks end on a rollout boundary, so siblings evaluate a rollout or
    more apart (9.03M and 9.07M at the "9M" chunk). Why not the k-th evaluation of each seed (the
    rule until the eleventh session): a seed run to 1M and one run to 2M in one chunk were
    paired, 1M with 2M. A point opens at the lowest step not yet grouped and takes each seed's
    evaluation up to SAME_POINT beyond it, one per seed; a seed paused off the grid (585,600 next
    to 500,000) makes its own point, and the table's seed count shows it. Each point has the
    seeds' `steps` and, per key of SPLITS, the success per episode of the trial of each seed that
    has it (sampled-action evaluations came later and exist only at some points)."""
    found = []
    for index, run in enumerate(seeds):
        by_step: dict[int, dict[str, list[float]]] = {}
        for e in run["evals"]:
            by_step.setdefault(e["step"], {})[e["split"] + ("_sampled" if e.get("sampled") else "")] = e["per_episode"]
        found += [(step, index, evals) for step, evals in by_step.items() if {"train", "test"} <= evals.keys()]
    groups: list[list[tuple[int, int, dict]]] = []
    for step, index, evals in sorted(found, key=lambda f: (f[0], f[1])):
        group = groups[-1] if groups else None
        if group is None or step > group[0][0] * (1 + SAME_POINT) + 20_000 or any(i == index for _, i, _ in group):
            groups.append([])
        groups[-1].append((step, index, evals))
    return [{"steps": [step for step, _, _ in group],
             **{key: [evals[key] for _, _, evals in group if key in evals] for key in SPLITS}} for group in groups]


def episode_ends(curves: list[list[float]], count_seeds: bool) -> str:
    """Success at a trial's first and last episode, mean over the seeds that have `curves`
    ('-' where none has); with `count_seeds` the number of those seeds too (sampled-action
    evaluations exist for fewer seeds than the point has)."""
    if not curves:
        return "-"
    ends = f"{np.mean([c[0] for c in curves]):.2f} -> {np.mean([c[-1] for c in curves]):.2f}"
    return f"{ends} ({len(curves)})" if count_seeds else ends


def plot_curves(runs: dict[str, dict], out: Path) -> Path:
    """Left: meta-test success at episode 1 (dashed) and episode K (solid) of a trial vs env steps,
    mean over seeds. Right: the adaptation curve (success at episode 1..K on held-out goals) at
    each variant's last evaluation that every one of its seeds reached."""
    plt = pyplot()

    fig, (ax, ax_adapt) = plt.subplots(1, 2, figsize=(11, 4), width_ratios=[3, 2])
    # every variant with runs, colours repeating (zip over the 10-colour cycle alone dropped all
    # variants after the tenth); ask for fewer --variants to read one comparison
    shown = [v for v in VARIANTS if any(r["variant"] == v for r in runs.values())]
    for colour, variant in zip(itertools.cycle(plt.rcParams["axes.prop_cycle"].by_key()["color"]), shown):
        seeds = [r for r in runs.values() if r["variant"] == variant]
        points = evaluation_points(seeds)
        if not points:
            continue
        steps = [np.mean(p["steps"]) for p in points]
        for k, style in ((0, "--"), (-1, "-")):
            mean = [np.mean([curve[k] for curve in p["test"]]) for p in points]
            label = f"{variant}, episode {1 if k == 0 else len(points[0]['test'][0])} ({len(seeds)} seed{'s' * (len(seeds) > 1)})"
            ax.plot(steps, mean, style, marker="o", color=colour, label=label)
        complete = [p for p in points if len(p["steps"]) == len(seeds)]
        if complete:
            curve = np.mean(complete[-1]["test"], axis=0)
            at = f"{int(np.mean(complete[-1]['steps'])):,}"
            ax_adapt.plot(range(1, len(curve) + 1), curve, "o-", color=colour, label=f"{variant} at ~{at} steps")
    ax.set_xlabel("environment steps")
    ax.set_ylabel("meta-test success (held-out goals)")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(fontsize=7, handlelength=4)  # long enough handles to show episode 1's dashes
    ax.set_title("ML1, goal hidden: meta-test success vs steps")
    ax_adapt.set_xticks(range(1, 1 + max((len(r["evals"][0]["per_episode"]) for r in runs.values() if r["evals"]), default=TRIAL_EPISODES)))
    ax_adapt.set_xlabel("episode of the trial")
    ax_adapt.set_ylim(-0.02, 1.02)
    ax_adapt.legend(fontsize=7)
    ax_adapt.set_title("adaptation curve (mean over seeds)")
    return save_figure(fig, out)


def main() -> None:
    parser = chunked_parser(__doc__, chunk_steps=500_000)
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    parser.add_argument("--steps", type=int, default=2_000_000)
    parser.add_argument("--trials", type=int, default=50, help="trials per split per evaluation (goal k for trial k)")
    args = parser.parse_args()

    runs = {}
    for variant in args.variants:
        for seed in args.seeds:
            run_dir = RUNS / f"{variant}-seed{seed}"
            run = RunDir(run_dir)
            if not args.report_only:
                start = time.perf_counter()
                step = advance_run(VARIANTS[variant], run_dir, seed, args.steps, args.chunk_steps)
                for sampled in (False, True):  # a finished run gets any evaluation it lacks
                    meta_evaluate(run_dir, step, args.trials, sampled)
                evaluate_starting_point(run_dir, args.trials)
                print(f"{variant} seed {seed}: {step:,} / {args.steps:,} steps ({time.perf_counter() - start:.0f} s this call)", flush=True)
            if not run.metrics.exists():
                continue
            metrics = run.read_metrics()
            # a run's own length (what --steps was when it started), so a report made with other
            # --steps, or with none (2M), still says what is left of the 10M runs
            total = json.loads(run.config.read_text())["total_steps"] if run.config.exists() else args.steps
            runs[f"{variant}-seed{seed}"] = {
                "variant": variant, "seed": seed, "steps_done": run.steps_done(), "total_steps": total,
                "evals": [e for e in read_jsonl(run_dir / "meta_evals.jsonl") if e["trials"] == args.trials],
                "train_last_episode_success": [(m["step"], m["success_rate"]) for m in metrics if m.get("success_rate") is not None],
                "steps_per_s": float(np.median([m["steps_per_s"] for m in metrics if "steps_per_s" in m])),  # not in an evaluation-only record (step 0 of an init_from run)
            }

    rows = []
    for variant in args.variants:
        for point in evaluation_points([r for r in runs.values() if r["variant"] == variant]):
            low, high = min(point["steps"]), max(point["steps"])
            rows.append([variant, f"{low:,}" if low == high else f"{low:,}-{high:,}", len(point["steps"]),
                         *(episode_ends(point[key], count_seeds=key.endswith("sampled")) for key in SPLITS)])
    episodes = "ep 1 -> K"
    print_table(["variant", "env steps", "seeds", f"meta-train {episodes}", f"meta-test {episodes}",
                 f"sampled: meta-train {episodes} (seeds)", f"sampled: meta-test {episodes} (seeds)"], rows)
    missing = len(args.variants) * len(args.seeds) - len(runs)
    remaining = sum(max(0, r["total_steps"] - r["steps_done"]) for r in runs.values()) + missing * args.steps
    print(f"remaining: {remaining:,} env steps ({len(runs)} runs started, {missing} not started)")
    print(f"curves: {plot_curves(runs, RESULTS / 'rl2_ml1.png')}")
    write_result("rl2_ml1", {"variants": args.variants, "seeds": args.seeds, "steps": args.steps, "trials": args.trials,
                             "trial_episodes": {r["variant"]: len(r["evals"][0]["per_episode"]) for r in runs.values() if r["evals"]}, "runs": runs, "remaining_steps": remaining,
                             "complete": remaining == 0})


if __name__ == "__main__":
    main()
