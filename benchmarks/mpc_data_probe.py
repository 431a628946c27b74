"""What an MPC run's own data holds: in each window of its transitions, how often the object moved,
how often it moved toward the goal, how often the hand was at the object and how often the object
rose. Why: on push the same config took off on one seed and not on another (benchmarks/RESULTS.md);
a model can only learn to push toward the goal from steps that did, so counting them in each run's
buffer says whether the runs differ in what they collected before they differ in success. The
touch and lift counts say the same for pick-place, whose model must see a lift to plan one.

A second table follows the run's own episodes through the task, by the window each began in: how
many the hand reached the object in, lifted it in, brought it within the success distance of the
goal in, and ended there. Why: a run whose success stalls stalls at one of these steps (the hand
never gets there, the grasp slips, the carry misses, the puck is dropped after arriving), and each
asks for a different fix.

    python benchmarks/mpc_data_probe.py benchmarks/runs/model_based/mpc-push-large-seed0/final.pt
                                        benchmarks/runs/model_based/mpc-push-large-seed1/checkpoint.pt
                                        [--window 20000] [--moved 0.005] [--closer 0.003] [--near 0.02]
                                        [--rose 0.005] [--lifted 0.02] [--success 0.07]
                                        [--out mpc_data_probe]

Each checkpoint's buffer (`algo: mpc`) is read oldest first; a row is one env step of one env
(a warm start's demos come first). The object's motion is read off the `goal - object` features
that `observation.relative_positions` appends (the goal stays put within an episode, so their
change is minus the object's), the hand's reach off `object - tool`: the run's task must append
them and observe its goal.

Writes benchmarks/results/<out>.json.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402
from taskforge.agents import MPCAgent  # noqa: E402
from taskforge.run import LoadedRun, load_run  # noqa: E402
from taskforge.spec.errors import SpecError  # noqa: E402


def object_run(checkpoint: Path, why_mpc: str) -> LoadedRun:
    """The `algo: mpc` run at `checkpoint`, whose task appends `object - tool, goal - object` and
    observes its goal; a one-line error (SystemExit) otherwise, or where there is no run, `why_mpc` saying why only an MPC
    run will do. Shared with `mpc_push_probe.py`, which reads the object's motion the same way."""
    try:
        run = load_run(checkpoint)
    except SpecError as exc:  # no policy there, or not a taskforge run: one line, not a traceback
        sys.exit(f"error: {exc}")
    if not isinstance(run.agent, MPCAgent):
        sys.exit(f"error: {checkpoint}: not an algo: mpc run ({why_mpc})")
    task, task_file, _ = run.phases[-1]
    if not (task.observation.relative_positions and task.goals.observable):
        sys.exit(f"error: {checkpoint}: its task ({task_file}) needs observation.relative_positions: true and "
                 "goals.observable: true (the object's motion is read off `goal - object`)")
    return run


def relative_positions(checkpoint: Path) -> tuple[np.ndarray, np.ndarray, int]:
    """`object - tool, goal - object` before and after every transition of the run's buffer,
    oldest first, and the run's step. A one-line error (SystemExit) where the run cannot tell the
    object's motion."""
    run = object_run(checkpoint, "only its buffer holds the data it collected")
    buffer = run.agent.buffer
    order = buffer.oldest_first()
    return buffer.obs[order, -6:].numpy(), buffer.next_obs[order, -6:].numpy(), run.agent.global_step


def count_contacts(before: np.ndarray, after: np.ndarray, window: int, moved: float, closer: float,
                   near: float, rose: float) -> list[dict]:
    """Per window of `window` transitions (rows of `object - tool, goal - object`): those where the
    object moved more than `moved` metres, those of them that brought it more than `closer`
    metres nearer the goal, those that began with the hand within `near` metres of the object,
    and those where the object rose more than `rose` metres (the goal's height is fixed in an
    episode, so `goal - object`'s height fell by as much)."""
    motion = np.linalg.norm(after[:, 3:] - before[:, 3:], axis=1)
    gain = np.linalg.norm(before[:, 3:], axis=1) - np.linalg.norm(after[:, 3:], axis=1)
    reach = np.linalg.norm(before[:, :3], axis=1)
    rise = before[:, 5] - after[:, 5]
    rows = []
    for start in range(0, len(motion), window):
        part = slice(start, start + window)
        m, g = motion[part], gain[part]
        rows.append({"from": start, "to": start + len(m), "moved": int((m > moved).sum()),
                     "toward_goal": int(((m > moved) & (g > closer)).sum()),
                     "at_object": int((reach[part] < near).sum()), "rose": int((rise[part] > rose).sum())})
    return rows


def episodes(before: np.ndarray, after: np.ndarray, lookahead: int = 64) -> list[np.ndarray]:
    """The buffer's rows grouped into episodes, each oldest first. Why this way: the buffer keeps
    no episode ends and interleaves its envs, but a step's next observation is, bit for bit, the
    observation the same env's next step began from, a few rows on (as many as there are envs;
    demos run one env); a row no later row continues (within `lookahead`) ended its episode
    (an autoreset begins the next one elsewhere). A run resumed in chunks resets its envs at each
    resume, so the episodes then under way end there, short: they count as episodes too."""
    successor = np.full(len(before), -1)
    for k in range(lookahead, 0, -1):  # the nearest match wins: written last
        match = np.flatnonzero((after[:-k] == before[k:]).all(axis=1))
        successor[match] = match + k
    continued = np.zeros(len(before), dtype=bool)
    continued[successor[successor >= 0]] = True
    chains = []
    for start in np.flatnonzero(~continued):
        rows = [start]
        while successor[rows[-1]] >= 0:
            rows.append(successor[rows[-1]])
        chains.append(np.asarray(rows))
    return chains


def episode_funnel(before: np.ndarray, after: np.ndarray, window: int, near: float, lifted: float,
                   success: float) -> list[dict]:
    """Per window of `window` transitions, the episodes that began in it and, of them, those in
    which the hand came within `near` metres of the object, the object rose `lifted` metres above
    where it began, came within `success` metres of the goal, and was within it at the
    episode's last step (Meta-World's success is the first of these two, at any step)."""
    rows = [{"from": start, "to": min(start + window, len(before)), "episodes": 0, "reached": 0, "lifted": 0,
             "at_goal": 0, "ended_at_goal": 0} for start in range(0, len(before), window)]
    for chain in episodes(before, after):
        states = np.concatenate([before[chain[:1]], after[chain]])  # object - tool, goal - object
        to_goal = np.linalg.norm(states[:, 3:], axis=1)
        row = rows[chain[0] // window]
        row["episodes"] += 1
        row["reached"] += int(np.linalg.norm(states[:, :3], axis=1).min() < near)
        row["lifted"] += int((states[0, 5] - states[:, 5]).max() > lifted)  # the goal's height is fixed
        row["at_goal"] += int(to_goal.min() < success)
        row["ended_at_goal"] += int(to_goal[-1] < success)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("checkpoints", type=Path, nargs="+")
    parser.add_argument("--window", type=int, default=20_000, help="transitions per row")
    # Meta-World's puck moves up to ~1 cm a step under a push; 1 mm of sensor noise on each
    # coordinate (the tasks' per-step noise) makes a 5 mm jump by chance in ~0.2 % of the steps
    parser.add_argument("--moved", type=float, default=0.005, help="metres the object moves in one step to count")
    parser.add_argument("--closer", type=float, default=0.003, help="metres nearer the goal for a move to count as toward it")
    parser.add_argument("--near", type=float, default=0.02, help="metres from the object for the hand to count as at it")
    # the tasks' 1 mm of per-step sensor noise moves `goal - object`'s height by 1.4 mm (std) from
    # one step to the next: 5 mm is 3.5 std, by chance in ~0.02 % of the steps
    parser.add_argument("--rose", type=float, default=0.005, help="metres the object rises in one step to count")
    parser.add_argument("--lifted", type=float, default=0.02, help="metres above its start for an episode to count as a lift")
    parser.add_argument("--success", type=float, default=0.07, help="metres from the goal that count as there (Meta-World pick-place: 0.07)")
    parser.add_argument("--out", default="mpc_data_probe", help="results file name, without .json")
    args = parser.parse_args()
    runs, table, funnel = {}, [], []
    for checkpoint in args.checkpoints:
        before, after, step = relative_positions(checkpoint)
        rows = count_contacts(before, after, args.window, args.moved, args.closer, args.near, args.rose)
        ends = episode_funnel(before, after, args.window, args.near, args.lifted, args.success)
        runs[str(checkpoint)] = {"step": step, "transitions": len(before), "windows": rows, "episodes": ends}
        funnel += [[checkpoint.parent.name, f"{r['from']:,}-{r['to']:,}", r["episodes"], r["reached"], r["lifted"],
                    r["at_goal"], r["ended_at_goal"]] for r in ends]
        table += [[checkpoint.parent.name, f"{r['from']:,}-{r['to']:,}", r["moved"], r["toward_goal"],
                   f"{r['toward_goal'] / max(r['moved'], 1):.2f}", r["at_object"], r["rose"]] for r in rows]
    print_table(["run", "transitions", f"object moved > {args.moved * 1000:g} mm", f"of them > {args.closer * 1000:g} mm nearer the goal",
                 "share toward the goal", f"hand < {args.near * 100:g} cm from it", f"object rose > {args.rose * 1000:g} mm"], table)
    print_table(["run", "episodes begun in", "episodes", f"hand < {args.near * 100:g} cm from the object",
                 f"object lifted > {args.lifted * 100:g} cm", f"object < {args.success * 100:g} cm from the goal",
                 "and there at the end"], funnel)
    payload = {"window": args.window, "moved": args.moved, "closer": args.closer, "near": args.near, "rose": args.rose,
               "lifted": args.lifted, "success": args.success, "runs": runs}
    print(f"wrote {write_result(args.out, payload)}")


if __name__ == "__main__":
    main()
