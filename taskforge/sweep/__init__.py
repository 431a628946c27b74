"""`taskforge sweep`: many seeds x variants of a curriculum as Ray tasks, evaluated under test
conditions and tabled as Learning Dexterity's ablations were. Above training and evaluation in
the package's arrows: it runs the one and then the other."""

from taskforge.sweep.plan import SweepPlan, Trial, plan_sweep
from taskforge.sweep.runner import SweepInterrupted, run_sweep
from taskforge.sweep.table import format_markdown, summarize_seeds, sweep_table

__all__ = ["SweepInterrupted", "SweepPlan", "Trial", "format_markdown", "plan_sweep", "run_sweep", "summarize_seeds", "sweep_table"]
