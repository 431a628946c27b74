"""Loading another run's learnt weights into an agent built for a new curriculum (`init_from`).

Why a check of its own: torch's `load_state_dict` reports a mismatch as a multi-line
RuntimeError listing every tensor; a user who pointed a curriculum at the wrong run needs one
line naming the first tensor that differs and what each side has.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch


class WeightsMismatch(ValueError):
    """The loaded weights do not fit the agent (another algo, network size or observation)."""


def load_matching(module: torch.nn.Module, state: Mapping[str, torch.Tensor], what: str) -> None:
    """`module.load_state_dict(state)` once every tensor's name and shape agree; else
    `WeightsMismatch` naming the first difference (`what` names the module in the message)."""
    own = module.state_dict()
    missing = sorted(set(own) - set(state))
    extra = sorted(set(state) - set(own))
    if missing or extra:
        side = f"lacks '{missing[0]}'" if missing else f"has '{extra[0]}', which this agent does not"
        raise WeightsMismatch(f"its {what} {side}")
    for name, tensor in own.items():
        if tuple(state[name].shape) != tuple(tensor.shape):
            raise WeightsMismatch(f"its {what} '{name}' has shape {tuple(state[name].shape)}, this agent builds {tuple(tensor.shape)}")
    module.load_state_dict(state)


def require(state: Mapping[str, object], keys: tuple[str, ...], algo: str) -> None:
    """A state from another kind of agent (PPO's `policy` against MPC's `model`) fails here, before
    any tensor is compared."""
    absent = [k for k in keys if k not in state]
    if absent:
        raise WeightsMismatch(f"it holds no '{absent[0]}': not the state of an {algo} agent")
