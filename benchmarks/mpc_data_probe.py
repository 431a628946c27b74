"""What an MPC run's own data holds: in each window of its transitions, how often the object moved,
how often it moved toward the goal, how often the hand was at the object and how often the object
rose. Why: on push the same config took off on one seed and not on another (benchmarks/RESULTS.md);
a model can only learn to push toward the goal from steps that did, so counting them in each run's
buffer says whether the runs differ in what they collected before they differ in success. The
touch and lift counts say the same for pick-place, whose model must see a lift to plan one.

    python benchmarks/mpc_data_probe.py benchmarks/runs/model_based/mpc-push-large-seed0/final.pt
                                        benchmarks/runs/model_based/mpc-push-large-seed1/checkpoint.pt
                                        [--window 20000] [--moved 0.005] [--closer 0.003] [--near 0.02]
                                        [--rose 0.005] [--out mpc_data_probe]

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
from taskforge.run import load_run  # noqa: E402


def relative_positions(checkpoint: Path) -> tuple[np.ndarray, np.ndarray, int]:
    """`object - tool, goal - object` before and after every transition of the run's buffer,
    oldest first, and the run's step. A one-line error (SystemExit) where the run cannot tell the
    object's motion."""
    run = load_run(checkpoint)
    if not isinstance(run.agent, MPCAgent):
        sys.exit(f"error: {checkpoint}: not an algo: mpc run (only its buffer holds the data it collected)")
    task, task_file, _ = run.phases[-1]
    if not (task.observation.relative_positions and task.goals.observable):
        sys.exit(f"error: {checkpoint}: its task ({task_file}) needs observation.relative_positions: true and "
                 "goals.observable: true (the object's motion is read off `goal - object`)")
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
    parser.add_argument("--out", default="mpc_data_probe", help="results file name, without .json")
    args = parser.parse_args()
    runs, table = {}, []
    for checkpoint in args.checkpoints:
        before, after, step = relative_positions(checkpoint)
        rows = count_contacts(before, after, args.window, args.moved, args.closer, args.near, args.rose)
        runs[str(checkpoint)] = {"step": step, "transitions": len(before), "windows": rows}
        table += [[checkpoint.parent.name, f"{r['from']:,}-{r['to']:,}", r["moved"], r["toward_goal"],
                   f"{r['toward_goal'] / max(r['moved'], 1):.2f}", r["at_object"], r["rose"]] for r in rows]
    print_table(["run", "transitions", f"object moved > {args.moved * 1000:g} mm", f"of them > {args.closer * 1000:g} mm nearer the goal",
                 "share toward the goal", f"hand < {args.near * 100:g} cm from it", f"object rose > {args.rose * 1000:g} mm"], table)
    payload = {"window": args.window, "moved": args.moved, "closer": args.closer, "near": args.near, "rose": args.rose, "runs": runs}
    print(f"wrote {write_result(args.out, payload)}")


if __name__ == "__main__":
    main()
