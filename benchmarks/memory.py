"""Peak memory of a pick-place training run (main process + vector-env workers).

    python benchmarks/memory.py [--steps 30000]

Runs `taskforge train curricula/pick_place.yaml` in a subprocess and samples, every 0.2 s, the
resident set (RSS) and proportional set (PSS: shared pages split between the processes that map
them, so forked workers are not double counted) of the whole process tree. Goal: <= 2 GiB.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GIB = 1024**3


def tree(pid: int) -> list[int]:
    pids, todo = [], [pid]
    while todo:
        p = todo.pop()
        pids.append(p)
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                todo += [int(c) for c in (task / "children").read_text().split()]
            except OSError:
                pass
    return pids


def memory_kib(pid: int) -> tuple[int, int]:
    """(RSS, PSS) of one process in KiB, from /proc/<pid>/smaps_rollup."""
    rss = pss = 0
    try:
        for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
            if line.startswith("Rss:"):
                rss = int(line.split()[1])
            elif line.startswith("Pss:"):
                pss = int(line.split()[1])
    except OSError:
        pass
    return rss, pss


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30_000)
    parser.add_argument("--curriculum", default=str(ROOT / "curricula/pick_place.yaml"))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        proc = subprocess.Popen(
            [sys.executable, "-m", "taskforge.cli", "train", args.curriculum, "--run-dir", f"{tmp}/run",
             "--steps", str(args.steps), "--no-progress"], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )
        peak_rss = peak_pss = peak_procs = 0
        while proc.poll() is None:
            pids = tree(proc.pid)
            usage = [memory_kib(p) for p in pids]
            peak_rss = max(peak_rss, sum(u[0] for u in usage))
            peak_pss = max(peak_pss, sum(u[1] for u in usage))
            peak_procs = max(peak_procs, len(pids))
            time.sleep(0.2)
        err = proc.stderr.read().decode()
    if proc.returncode != 0:
        raise SystemExit(f"training failed ({proc.returncode}):\n{err}")
    print_table(["measure", "peak (GiB)"], [["RSS, summed over processes", f"{peak_rss * 1024 / GIB:.3f}"],
                                            ["PSS, summed (shared pages counted once)", f"{peak_pss * 1024 / GIB:.3f}"]])
    print(f"{peak_procs} processes; goal <= 2 GiB: {'met' if peak_pss * 1024 <= 2 * GIB else 'NOT met'} (PSS)")
    write_result("memory", {"curriculum": args.curriculum, "steps": args.steps, "processes": peak_procs,
                            "peak_rss_gib": peak_rss * 1024 / GIB, "peak_pss_gib": peak_pss * 1024 / GIB, "goal": "<= 2 GiB"})


if __name__ == "__main__":
    main()
