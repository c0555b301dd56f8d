"""The hierarchical agent's per-step state, declared once: what both of its step paths read at
``s`` and write for ``s'``.

:class:`StepState` holds, for all P agents, the current state ``s``, the decision in force
(what it is, where it was taken, its return and duration so far) and the action taken at
``s``. :class:`~skillchain_torch.agents.HierarchicalAgent` owns one (``agent.step_state``):
its torch path reads and replaces the fields, and its compiled path hands the whole state to
:func:`skillchain_torch.backends.hierarchical.transition`, which returns the state at ``s'``.
Each field also reads and writes as the agent's attribute (``agent.obs is
agent.step_state.obs``), so the torch path reads as the paper's rules.

Fields are replaced, never written in place, by the torch path; the compiled path writes
``option_code``, ``decision_phi`` and ``state_phi`` in place (each row is read before it is
written), so the arrays are the agent's own and nothing else may hold them.

Example:
    >>> state = StepState.start(population=2, slots=3, obs_dim=4, num_features=16,
    ...                         option_code=torch.ones(2, 8, dtype=torch.float64))
    >>> state.obs.shape, state.option.tolist(), state.state_phi.shape
    (torch.Size([2, 4]), [-1, -1], torch.Size([2, 0]))
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import torch
from torch import Tensor

__all__ = ["STEP_FIELDS", "StepState"]


@dataclass(slots=True)
class StepState:
    """The state at ``s`` of P agents (float64 unless noted; ``F``: the top level's features,
    ``Fo``: the option heads' code, ``K``: option slots)."""

    obs: Tensor  #: ``[P, obs_dim]``: ``s``
    option_code: Tensor  #: ``[P, Fo]``: the option heads' code of ``s``
    contains: Tensor  #: ``[P, K]`` bool: ``s`` in each option's initiation set (for choosing)
    #: ``[P, K]`` bool: ``s`` in each option's own set (the classifier's, before skill
    #: chaining's no-overlap narrowing): where option k learns off-policy
    #: (:func:`~skillchain_torch.objectives.option_update_mask`)
    own_contains: Tensor
    decision_phi: Tensor  #: ``[P, F]``: the features where the decision in force was taken
    decision: Tensor  #: ``[P]`` int64: the decision in force (a primitive, or 5 + slot)
    option: Tensor  #: ``[P]`` int64: the executing option's slot, -1 for none
    action: Tensor  #: ``[P]`` int64: the primitive taken at ``s``
    decision_return: Tensor  #: ``[P]``: the decision's (discounted) return so far
    duration: Tensor  #: ``[P]`` int64: the decision's steps so far
    #: ``[P, F]`` (``[P, 0]`` unless intra_option_primitives): ``phi(s)``, where an option's
    #: step updates the primitive's value (not where the decision in force was taken)
    state_phi: Tensor

    @classmethod
    def start(cls, population: int, slots: int, obs_dim: int, num_features: int,
              option_code: Tensor, state_phi: bool = False) -> StepState:  # fmt: skip
        """Agents before their first episode: at the zero state, with no decision and no
        option (``option_code``: the option heads' code of the zero state)."""
        P, device = population, option_code.device
        f64 = dict(dtype=torch.float64, device=device)
        i64 = dict(dtype=torch.int64, device=device)
        return cls(
            obs=torch.zeros(P, obs_dim, **f64), option_code=option_code,
            contains=torch.zeros(P, slots, dtype=torch.bool, device=device),
            own_contains=torch.zeros(P, slots, dtype=torch.bool, device=device),
            decision_phi=torch.zeros(P, num_features, **f64),
            decision=torch.zeros(P, **i64), option=torch.full((P,), -1, **i64),
            action=torch.zeros(P, **i64), decision_return=torch.zeros(P, **f64),
            duration=torch.zeros(P, **i64),
            state_phi=torch.zeros(P, num_features if state_phi else 0, **f64),
        )  # fmt: skip


STEP_FIELDS = tuple(field.name for field in fields(StepState))
