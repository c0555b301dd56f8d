"""SMDP Sarsa as a TorchRL loss module: how any top-level value head learns (paper section 2).

:class:`~skillchain_torch.objectives.SarsaUpdate` moves the built-in linear head in closed form.
:class:`SMDPSarsaLoss` is the same rule as a loss, so a head of the user's own (an MLP, say)
trains by any torch optimizer: a decision ``d`` taken in ``s`` that lasted ``k`` steps and
earned ``R`` has the target ``R + gamma^k Q(s', d')`` (none where the episode terminated), held
fixed (semi-gradient), and the loss is ``1/2 sum_p active_p (target_p - Q(s_p, d_p))^2``.
The sum (not the mean) over agents keeps each agent's gradient its own: plain SGD at ``lr =
alpha`` on a linear head is then exactly the closed-form step, ``w_d += alpha delta phi(s)``
(``tests/modules/test_sarsa_loss.py`` checks it to rounding).

Keys follow TorchRL's convention (``set_keys`` renames them; :attr:`default_keys`).

Example:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> from torch import nn
    >>> class Head(nn.Module):                       # Q(s, d) = w_d . phi(s), trainable
    ...     def __init__(self):
    ...         super().__init__()
    ...         self.w = nn.Parameter(torch.zeros(2, 3, 4, dtype=torch.float64))
    ...     def q_value(self, phi, decision, index=None):
    ...         return (self.w[torch.arange(2), decision] * phi).sum(-1)
    >>> loss = SMDPSarsaLoss(Head(), gamma=1.0)
    >>> td = TensorDict(phi=torch.ones(2, 4, dtype=torch.float64), decision=torch.tensor([0, 2]),
    ...                 decision_return=torch.tensor([-3.0, 5.0], dtype=torch.float64),
    ...                 duration=torch.tensor([3, 1]),
    ...                 next_value=torch.zeros(2, dtype=torch.float64),
    ...                 terminated=torch.tensor([False, True]),
    ...                 active=torch.tensor([True, True]), batch_size=[2])
    >>> out = loss(td)
    >>> out["loss"].item(), out["td_error"].tolist()
    (17.0, [-3.0, 5.0])
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torch import nn
from torchrl.objectives import LossModule

from skillchain_torch.objectives.sarsa import smdp_td_error

__all__ = ["SMDPSarsaLoss"]


class SMDPSarsaLoss(LossModule):
    """The top level's SMDP Sarsa loss for any value head with ``q_value(phi, decision)``.

    Args:
        value_head: the top-level head (:class:`~skillchain_torch.interfaces.ValueHead`); its
            ``q_value`` must be differentiable in its parameters.
        gamma: discount (paper: 1).

    ``forward(td)`` reads ``td [P]`` at the keys of :attr:`default_keys` and returns a
    ``TensorDict`` with ``loss`` (a scalar) and ``td_error [P]`` (0 for inactive agents,
    detached). ``next_value`` is ``Q(s', d')`` valued when ``d'`` was chosen; it is treated as
    a constant.
    """

    @dataclass
    class _AcceptedKeys:
        """Where :meth:`forward` reads each input (TorchRL's ``set_keys`` convention)."""

        features: NestedKey = "phi"
        decision: NestedKey = "decision"
        decision_return: NestedKey = "decision_return"
        duration: NestedKey = "duration"
        next_value: NestedKey = "next_value"
        terminated: NestedKey = "terminated"
        active: NestedKey = "active"

    default_keys = _AcceptedKeys

    def __init__(self, value_head: nn.Module, gamma: float = 1.0):
        super().__init__()
        self.value_head = value_head
        self.gamma = float(gamma)

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        pass  # the target is the SMDP one above, not a TorchRL value estimator

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        keys = self.tensor_keys
        active = tensordict.get(keys.active).to(torch.bool)
        q_sa = self.value_head.q_value(tensordict.get(keys.features), tensordict.get(keys.decision))
        delta = smdp_td_error(tensordict.get(keys.decision_return), tensordict.get(keys.duration),
                              q_sa, tensordict.get(keys.next_value).detach().to(q_sa.dtype),
                              tensordict.get(keys.terminated), self.gamma)  # fmt: skip
        delta = torch.where(active, delta, torch.zeros_like(delta))
        loss = 0.5 * (delta * delta).sum()
        return TensorDict(loss=loss, td_error=delta.detach(), batch_size=[])
