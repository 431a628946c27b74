"""Demonstration steps laid out as a policy reads them, so behaviour cloning, the exploration fit
and PPO's demonstration term work for feed-forward and recurrent policies alike.

An MLP reads each step on its own: one row of single steps. A recurrent policy must read a step
after the ones before it in its episode, from the state it had there, so its rows are whole
episodes (cut into chunks of at most `max_len` steps, each from a fresh state: the only
approximation, for episodes longer than any shipped task's), padded to a common length, with a
mask over the padding. Padding comes after a sequence's steps, so it never changes their outputs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

MAX_SEQUENCE = 500
"""Longest demo sequence a recurrent policy is cloned on: every shipped task's episode fits."""


@dataclass(frozen=True)
class DemoRows:
    """`index[t, b]`: the demo step at time t of row b; `mask[t, b]`: a real step, not padding."""

    index: torch.Tensor
    mask: torch.Tensor

    @property
    def width(self) -> int:
        return self.index.shape[1]

    @property
    def starts(self) -> torch.Tensor:
        """Episode-start flags for the policy: every row starts a sequence at t = 0."""
        starts = torch.zeros(self.index.shape, dtype=torch.bool)
        starts[0] = True
        return starts

    def take(self, columns: torch.Tensor) -> DemoRows:
        """The rows `columns`, without the time steps that are padding in all of them."""
        mask = self.mask[:, columns]
        length = int(mask.sum(dim=0).max())
        return DemoRows(self.index[:length, columns], mask[:length])


def demo_rows(episode_starts: np.ndarray, recurrent: bool, max_len: int = MAX_SEQUENCE) -> DemoRows:
    """The rows of `len(episode_starts)` concatenated demo steps (see the module doc)."""
    n = len(episode_starts)
    if not recurrent:
        return DemoRows(torch.arange(n)[None], torch.ones((1, n), dtype=torch.bool))
    starts = sorted({0, *np.flatnonzero(np.asarray(episode_starts, dtype=bool)).tolist()})
    chunks = [
        (begin, min(begin + max_len, end))
        for first, end in zip(starts, [*starts[1:], n])
        for begin in range(first, end, max_len)
    ]
    length = max(end - begin for begin, end in chunks)
    index = torch.zeros((length, len(chunks)), dtype=torch.long)
    mask = torch.zeros((length, len(chunks)), dtype=torch.bool)
    for b, (begin, end) in enumerate(chunks):
        index[: end - begin, b] = torch.arange(begin, end)
        mask[: end - begin, b] = True
    return DemoRows(index, mask)


def columns_per_batch(rows: DemoRows, steps: int) -> int:
    """How many rows make a minibatch of about `steps` demo steps."""
    return max(1, steps // rows.index.shape[0])
