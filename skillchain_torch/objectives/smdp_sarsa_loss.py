"""SMDP Sarsa as a TorchRL loss module: how any top-level value head learns (paper section 2).

:class:`~skillchain_torch.objectives.SarsaUpdate` moves the built-in linear head in closed form.
:class:`SMDPSarsaLoss` is the same rule as a loss, so a head of the user's own (an MLP, say)
trains by any torch optimizer: a decision ``d`` taken in ``s`` that lasted ``k`` steps and
earned ``R`` has the target ``R + gamma^k Q(s', d')`` (none where the episode terminated), held
fixed (semi-gradient), and the loss is ``1/2 sum_p active_p (target_p - Q(s_p, d_p))^2``.
The sum (not the mean) over agents keeps each agent's gradient its own: plain SGD at ``lr =
alpha`` on a linear head is then exactly the closed-form step, ``w_d += alpha delta phi(s)``
(``tests/modules/test_losses.py`` checks it to rounding).

Keys follow TorchRL's convention (``set_keys`` renames them; :attr:`default_keys`).

**For neural heads** (DQN-style, as ``torchrl.objectives.DQNLoss``): ``loss_function="smooth_l1"``
(Huber), ``value_scale`` (the loss reads ``delta / value_scale``, so TD errors of order 10^4 make
gradients of order 10), and ``delay_value=True``, a target network (TorchRL's
``convert_to_functional(create_target_params=True)``; step it with ``torchrl.objectives.
HardUpdate`` or ``SoftUpdate``) that values ``s'`` from the keys ``next_phi`` and
``next_decision`` (the SMDP Sarsa target) or, with ``bootstrap="max"``, the best decision in
``next_available`` (SMDP Q-learning; ``double_dqn`` picks it by the online network). The defaults
are the paper's rule, unchanged.

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
from torch import Tensor, nn
from torch.nn import functional
from torchrl.objectives import LossModule

from skillchain_torch.objectives.sarsa import smdp_td_error

__all__ = ["LOSS_FUNCTIONS", "SMDPSarsaLoss"]

LOSS_FUNCTIONS = ("l2", "smooth_l1")


class SMDPSarsaLoss(LossModule):
    """The top level's SMDP Sarsa loss for any value head with ``q_value(phi, decision)``.

    Args:
        value_head: the top-level head (:class:`~skillchain_torch.interfaces.ValueHead`); its
            ``q_value`` and ``forward`` must be differentiable in its parameters and accept
            leading batch dims (``[B, P, F]``) when the loss reads replayed minibatches.
        gamma: discount (paper: 1).
        loss_function: ``"l2"`` (``1/2 delta^2``, the paper's semi-gradient) or ``"smooth_l1"``
            (Huber at 1, on the scaled error).
        value_scale: the loss reads ``delta / value_scale`` (1: the rule as stated).
        delay_value: keep target parameters; ``s'`` is then valued by them from ``next_phi``.
        bootstrap: ``"sarsa"`` (``Q(s', d')``) or ``"max"`` (``max_{d in next_available}``);
            only with ``delay_value`` (without it the caller's ``next_value`` is the target).
        double_dqn: with ``bootstrap="max"``, choose ``d'`` by the online parameters.

    ``forward(td)`` reads ``td [*B, P]`` at the keys of :attr:`default_keys` and returns a
    ``TensorDict`` with ``loss`` (a scalar: summed over agents, averaged over ``B``) and
    ``td_error [*B, P]`` (unscaled, 0 for inactive agents, detached). Without ``delay_value``,
    ``next_value`` is ``Q(s', d')`` valued when ``d'`` was chosen, treated as a constant.
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
        next_features: NestedKey = "next_phi"
        next_decision: NestedKey = "next_decision"
        next_available: NestedKey = "next_available"

    default_keys = _AcceptedKeys
    value_head: nn.Module
    value_head_params: TensorDictBase
    target_value_head_params: TensorDictBase

    def __init__(self, value_head: nn.Module, gamma: float = 1.0, *, loss_function: str = "l2",
                 value_scale: float = 1.0, delay_value: bool = False, bootstrap: str = "sarsa",
                 double_dqn: bool = False):  # fmt: skip
        super().__init__()
        if loss_function not in LOSS_FUNCTIONS:
            raise ValueError(f"loss_function must be one of {LOSS_FUNCTIONS}, "
                             f"got {loss_function!r}")  # fmt: skip
        if bootstrap not in ("sarsa", "max"):
            raise ValueError(f"bootstrap must be 'sarsa' or 'max', got {bootstrap!r}")
        if not value_scale > 0:
            raise ValueError(f"value_scale must be > 0, got {value_scale}")
        self.gamma, self.loss_function = float(gamma), loss_function
        self.value_scale, self.delay_value = float(value_scale), bool(delay_value)
        self.bootstrap, self.double_dqn = bootstrap, bool(double_dqn)
        if self.delay_value:
            self.convert_to_functional(value_head, "value_head", create_target_params=True)
        else:
            self.value_head = value_head

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        pass  # the target is the SMDP one above, not a TorchRL value estimator

    @torch.no_grad()
    def _target_value(self, tensordict: TensorDictBase) -> Tensor:
        """``Q'(s', d')`` (or the best available) by the target parameters."""
        keys = self.tensor_keys
        phi_next = tensordict.get(keys.next_features)
        with self.target_value_head_params.to_module(self.value_head):
            q_next = self.value_head(phi_next)
        if self.bootstrap == "sarsa":
            choice = tensordict.get(keys.next_decision).to(torch.int64)
        else:
            available = tensordict.get(keys.next_available).to(torch.bool)
            ranked = q_next
            if self.double_dqn:
                with self.value_head_params.data.to_module(self.value_head):
                    ranked = self.value_head(phi_next)
            choice = ranked.masked_fill(~available, -torch.inf).argmax(-1)
        return q_next.gather(-1, choice[..., None])[..., 0]

    @torch.no_grad()
    def td_error(self, tensordict: TensorDictBase) -> Tensor:
        """``delta [*B, P]`` toward the caller's ``next_value`` by the online parameters, 0
        for inactive agents (what a learner reports per step; cheaper than :meth:`forward`)."""
        keys = self.tensor_keys
        q_sa = self.value_head.q_value(tensordict.get(keys.features), tensordict.get(keys.decision))
        delta = smdp_td_error(tensordict.get(keys.decision_return), tensordict.get(keys.duration),
                              q_sa, tensordict.get(keys.next_value).to(q_sa.dtype),
                              tensordict.get(keys.terminated), self.gamma)  # fmt: skip
        return torch.where(tensordict.get(keys.active).to(torch.bool), delta,
                           torch.zeros_like(delta))  # fmt: skip

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        keys = self.tensor_keys
        active = tensordict.get(keys.active).to(torch.bool)
        if self.delay_value:
            next_value = self._target_value(tensordict)
            with self.value_head_params.to_module(self.value_head):
                q_sa = self.value_head.q_value(tensordict.get(keys.features),
                                               tensordict.get(keys.decision))  # fmt: skip
        else:
            next_value = tensordict.get(keys.next_value).detach()
            q_sa = self.value_head.q_value(tensordict.get(keys.features),
                                           tensordict.get(keys.decision))  # fmt: skip
        delta = smdp_td_error(tensordict.get(keys.decision_return), tensordict.get(keys.duration),
                              q_sa, next_value.to(q_sa.dtype), tensordict.get(keys.terminated),
                              self.gamma)  # fmt: skip
        delta = torch.where(active, delta, torch.zeros_like(delta))
        if self.loss_function == "l2" and self.value_scale == 1.0:
            per_step = 0.5 * (delta * delta)  # the paper's rule, exactly
        else:
            scaled = delta / self.value_scale
            per_step = (0.5 * scaled * scaled if self.loss_function == "l2" else
                        functional.smooth_l1_loss(scaled, torch.zeros_like(scaled),
                                                  reduction="none"))  # fmt: skip
            per_step = torch.where(active, per_step, torch.zeros_like(per_step))
        loss = per_step.sum(-1).mean() if per_step.ndim > 1 else per_step.sum()
        return TensorDict(loss=loss, td_error=delta.detach(), batch_size=[])
