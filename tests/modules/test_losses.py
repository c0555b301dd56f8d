"""The learning rules as TorchRL loss modules: the built-in closed-form steps equal one SGD step
on the loss at the same step size, to rounding (issue 29)."""

from __future__ import annotations

import doctest

import torch
from tensordict import TensorDict
from torch import nn

import skillchain_torch.objectives.intra_option_loss as intra_option_loss
from skillchain_torch.modules import LinearQHead
from skillchain_torch.objectives import (
    IntraOptionQLearning,
    IntraOptionQLoss,
    SarsaUpdate,
    SMDPSarsaLoss,
)
from skillchain_torch.options import FourierOptionQHead

F64 = torch.float64


def as_parameter(module):
    """``module`` with its ``weight`` buffer turned into an ``nn.Parameter`` (same values)."""
    weight = module._buffers.pop("weight")
    module.weight = nn.Parameter(weight.clone())
    return module


def test_intra_option_closed_form_equals_the_losss_sgd_step():
    g = torch.Generator().manual_seed(0)
    P, K, alpha = 3, 4, 0.05
    closed = FourierOptionQHead(P, K, order=2, alpha=alpha)
    closed.weight.normal_(generator=g)
    by_loss = as_parameter(FourierOptionQHead(P, K, order=2, alpha=alpha))
    with torch.no_grad():
        by_loss.weight.copy_(closed.weight)
    obs = torch.rand(P, 4, generator=g, dtype=F64)
    next_obs = torch.rand(P, 4, generator=g, dtype=F64)
    action, reward = torch.tensor([0, 3, 4]), torch.tensor([-1.0, -5.0, -1.0], dtype=F64)
    terminated = torch.tensor([False, False, True])
    inside = torch.rand(P, K, generator=g) < 0.6
    reached = torch.rand(P, K, generator=g) < 0.3
    delta = IntraOptionQLearning(1.0, 100.0)(closed, obs, action, reward, next_obs, terminated,
                                             inside, reached)  # fmt: skip
    loss = IntraOptionQLoss(by_loss, gamma=1.0, completion_reward=100.0)
    optimizer = torch.optim.SGD(by_loss.parameters(), lr=alpha)
    out = loss(TensorDict(observation=obs, action=action, reward=reward, next_observation=next_obs,
                          terminated=terminated, target_reached=reached, mask=inside,
                          batch_size=[P]))  # fmt: skip
    out["loss"].backward()
    optimizer.step()
    torch.testing.assert_close(out["td_error"], delta, rtol=0, atol=1e-12)
    torch.testing.assert_close(by_loss.weight.detach(), closed.weight, rtol=0, atol=1e-12)
    assert bool((closed.weight != as_parameter(FourierOptionQHead(P, K, order=2)).weight).any())


def test_smdp_sarsa_closed_form_equals_the_losss_sgd_step():
    g = torch.Generator().manual_seed(1)
    P, D, F, alpha = 4, 6, 5, 0.01
    closed = LinearQHead(F, D, P)
    closed.weight.normal_(generator=g)
    by_loss = as_parameter(LinearQHead(F, D, P))
    with torch.no_grad():
        by_loss.weight.copy_(closed.weight)
    phi = torch.rand(P, F, generator=g, dtype=F64)
    decision = torch.tensor([0, 5, 2, 3])
    ret = torch.tensor([-3.0, -40.0, 10_000.0, -1.0], dtype=F64)
    duration = torch.tensor([3, 40, 1, 1])
    next_value = torch.rand(P, generator=g, dtype=F64)
    terminated, active = torch.tensor([False, False, True, False]), torch.tensor([1, 1, 1, 0]) > 0
    delta = SarsaUpdate(alpha)(closed, phi, decision, ret, duration, phi, decision, terminated,
                               active=active, next_value=next_value)  # fmt: skip
    optimizer = torch.optim.SGD(by_loss.parameters(), lr=alpha)
    out = SMDPSarsaLoss(by_loss)(TensorDict(phi=phi, decision=decision, decision_return=ret,
                                            duration=duration, next_value=next_value,
                                            terminated=terminated, active=active,
                                            batch_size=[P]))  # fmt: skip
    out["loss"].backward()
    optimizer.step()
    torch.testing.assert_close(out["td_error"], delta, rtol=0, atol=1e-12)
    torch.testing.assert_close(by_loss.weight.detach(), closed.weight, rtol=0, atol=1e-9)
    assert float(out["td_error"][3]) == 0.0  # the inactive agent neither learns nor reports


def test_loss_docstring_examples():
    assert doctest.testmod(intra_option_loss, raise_on_error=True).attempted > 0
