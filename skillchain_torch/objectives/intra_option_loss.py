"""Intra-option Q-learning as a TorchRL loss module: how any option head learns (section 5.1).

:class:`~skillchain_torch.objectives.IntraOptionQLearning` steps the built-in Fourier option
heads in closed form. :class:`IntraOptionQLoss` is the same rule as a loss over every option
slot, so an option head of the user's own trains by any torch optimizer: for each ``(p, k)`` in
``mask`` (the slots that learn from this transition: :func:`~skillchain_torch.objectives.
option_update_mask`), the target ``r + C T_k(s') + gamma max_a Q_k(s', a) (1 - (T_k(s') or
terminated))`` (:func:`option_td_target`, held fixed) and the loss
``1/2 sum_{p,k in mask} (target - Q_k(s_p, a_p))^2``. Summed, not averaged, so plain SGD at the
head's ``alpha`` on a linear head is the closed-form step (tested to rounding).

Example:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> from skillchain_torch.options import FourierOptionQHead
    >>> head = FourierOptionQHead(population=1, slots=2, order=1)
    >>> loss = IntraOptionQLoss(head, gamma=1.0, completion_reward=100.0)
    >>> obs = torch.zeros(1, 4, dtype=torch.float64)
    >>> td = TensorDict(observation=obs, action=torch.tensor([4]),
    ...                 reward=torch.tensor([-1.0], dtype=torch.float64), next_observation=obs,
    ...                 terminated=torch.tensor([False]),
    ...                 target_reached=torch.tensor([[True, True]]),
    ...                 mask=torch.tensor([[True, False]]), batch_size=[1])
    >>> out = loss(td)
    >>> out["loss"].item(), out["td_error"].tolist()
    (4900.5, [[99.0, 0.0]])
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torch import nn
from torchrl.objectives import LossModule

from skillchain_torch.objectives.q_learning import option_td_target

__all__ = ["IntraOptionQLoss"]


class IntraOptionQLoss(LossModule):
    """Every option slot's intra-option Q-learning loss for an option head ``obs [P, D] ->
    Q [P, K, A]`` (:class:`~skillchain_torch.interfaces.OptionHead`).

    Args:
        option_head: the heads of every ``(agent, slot)``; differentiable in its parameters.
        gamma: discount (paper: 1); completion_reward: ``C`` (float or ``[P, K]``).

    ``forward(td)`` returns ``loss`` (a scalar) and ``td_error [P, K]`` (0 off ``mask``).
    """

    @dataclass
    class _AcceptedKeys:
        """Where :meth:`forward` reads each input (TorchRL's ``set_keys`` convention)."""

        observation: NestedKey = "observation"
        action: NestedKey = "action"
        reward: NestedKey = "reward"
        next_observation: NestedKey = "next_observation"
        terminated: NestedKey = "terminated"
        target_reached: NestedKey = "target_reached"
        mask: NestedKey = "mask"

    default_keys = _AcceptedKeys

    def __init__(self, option_head: nn.Module, gamma: float = 1.0,
                 completion_reward: float = 10_000.0):  # fmt: skip
        super().__init__()
        self.option_head = option_head
        self.gamma = float(gamma)
        self.completion_reward = completion_reward

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        pass  # the target is the intra-option one, not a TorchRL value estimator

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        keys = self.tensor_keys
        mask = tensordict.get(keys.mask).to(torch.bool)
        with torch.no_grad():
            next_max = self.option_head(tensordict.get(keys.next_observation)).amax(-1)
            target = option_td_target(tensordict.get(keys.reward), next_max,
                                      tensordict.get(keys.target_reached),
                                      tensordict.get(keys.terminated), self.gamma,
                                      self.completion_reward)  # fmt: skip
        q = self.option_head(tensordict.get(keys.observation))  # [P, K, A]
        action = tensordict.get(keys.action).to(torch.int64)
        q_sa = q.gather(2, action[:, None, None].expand(-1, q.shape[1], 1))[..., 0]
        delta = torch.where(mask, target - q_sa, torch.zeros_like(q_sa))
        loss = 0.5 * (delta * delta).sum()
        return TensorDict(loss=loss, td_error=delta.detach(), batch_size=[])
