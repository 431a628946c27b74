"""The training loop, checkpoints (atomic), logging (TensorBoard, JSONL) and progress."""

from taskforge.training.checkpoint import load_checkpoint, save_checkpoint
from taskforge.training.trainer import CHECKPOINT, FINAL, FINAL_EVAL, Interrupted, train

__all__ = ["CHECKPOINT", "FINAL", "FINAL_EVAL", "Interrupted", "load_checkpoint", "save_checkpoint", "train"]
