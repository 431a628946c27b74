"""The training loop, warm start, DAgger and metrics logging. The run directory and checkpoints
they write live in `taskforge.run`."""

from taskforge.training.trainer import Interrupted, load_init_from, train

__all__ = ["Interrupted", "load_init_from", "train"]
