"""The top-level value head is swappable (issue 29): a head of the user's own learns by the
SMDP Sarsa loss module and any optimizer, and the built-in closed-form step equals the loss's
gradient step."""

from __future__ import annotations

import doctest

import pytest
import torch
from torch import nn

import skillchain_torch.objectives.smdp_sarsa_loss as smdp_sarsa_loss
from skillchain_torch.agents import HierarchicalAgent, SkillChainingAgent
from skillchain_torch.features import FourierBasis
from skillchain_torch.interfaces import ValueHead, missing_methods
from skillchain_torch.modules import LinearQHead, MLPQHead
from skillchain_torch.options import OptionBank
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

F64 = torch.float64


class ParameterLinearHead(LinearQHead):
    """The built-in linear head with its weights as an ``nn.Parameter``: trained by the loss
    module and SGD instead of the closed-form step."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        weight = self._buffers.pop("weight")
        self.weight = nn.Parameter(weight)


class MLPValueHead(nn.Module):
    """A user's neural top-level head on the raw observation: ``Q(s, .) = net(s) + offset``,
    one small MLP per agent, batched with ``torch.func``-free einsums; ``set_values`` writes
    the per-decision offset (how discovery starts a joining option's value)."""

    def __init__(self, population, num_decisions, hidden=16):
        super().__init__()
        self.population, self.num_decisions, self.num_features = population, num_decisions, 4
        g = torch.Generator().manual_seed(0)
        self.w1 = nn.Parameter(torch.randn(population, 4, hidden, generator=g, dtype=F64) * 0.5)
        self.w2 = nn.Parameter(torch.zeros(population, hidden, num_decisions, dtype=F64))
        self.register_buffer("offset", torch.zeros(population, num_decisions, dtype=F64))

    def forward(self, phi):
        h = torch.tanh(torch.einsum("pf,pfh->ph", phi, self.w1))
        return torch.einsum("ph,phd->pd", h, self.w2) * 100.0 + self.offset

    def forward_mask(self, phi, mask, dense=0):
        return torch.where(mask, self(phi), 0.0)

    def q_value(self, phi, decision, index=None):
        q = self(phi).gather(1, decision[:, None])[:, 0]
        return q if index is None else q[index]

    @torch.no_grad()
    def set_values(self, mask, value):
        self.offset.copy_(torch.where(mask, value.to(F64), self.offset))


def train(agent, runs, episodes=3, steps=400, seed=7):
    cfg = TrainConfig(agent="skill-chaining", runs=runs, episodes=episodes,
                      max_episode_steps=steps, seed=seed)  # fmt: skip
    return PopulationTrainer(cfg, agent=agent).train()


def test_the_closed_form_step_equals_the_loss_modules_sgd_step():
    """The same agents, once with the built-in head (closed form) and once with its weights
    as a Parameter (SMDPSarsaLoss + SGD at alpha): the same weights to rounding, the same
    returns."""
    runs = []
    for head in (None, ParameterLinearHead(81 * 0 + 16, 5 + 3, 2)):
        bank = OptionBank.build(2, 3, order=1, seed=7)
        agent = SkillChainingAgent(bank, order=1, seed=7, q_head=head, native=False,
                                   gestation=1)  # fmt: skip
        assert agent.closed_form is (head is None)
        runs.append((train(agent, 2), agent))
    (closed, a), (by_loss, b) = runs
    assert a.q_head.weight.abs().sum() > 0
    torch.testing.assert_close(b.q_head.weight.detach(), a.q_head.weight, rtol=0, atol=1e-9)
    assert (closed.returns == by_loss.returns).all()


def test_a_neural_top_level_head_learns_inside_skill_chaining():
    head = MLPValueHead(population=2, num_decisions=5 + 3)
    bank = OptionBank.build(2, 3, order=1, seed=3)
    # Adam's steps are bounded by its lr: plain SGD at these returns (thousands) diverges
    # (the trainer's divergence check says so, naming the top-level head).
    agent = SkillChainingAgent(bank, order=1, seed=3, q_head=head, features=nn.Identity(),
                               value_start="max-sample", policy_start="zero",
                               optimizer=torch.optim.Adam(head.parameters(), lr=1e-3))
    assert agent.native is False and isinstance(head, ValueHead)
    before = head.w2.detach().clone()
    trainer = train(agent, 2, episodes=2, steps=300, seed=3)
    assert trainer.agent_steps > 0
    assert not torch.equal(head.w2.detach(), before)
    assert all(torch.isfinite(p).all() for p in head.parameters())
    state = agent.state_dict()
    assert "optimizer" in state and "offset" in state["q_head"]


def test_starts_that_read_linear_weights_name_the_head():
    with pytest.raises(ValueError, match="value_start='agent'.*MLPValueHead cannot take.*"
                                         "needs fit_values and select_agents.*max-sample"):
        SkillChainingAgent(OptionBank.build(1, 2, order=1), order=1,
                           q_head=MLPValueHead(1, 7), features=nn.Identity(),
                           value_start="agent")  # fmt: skip
    # the policy copy reads the agent's values one agent at a time: refused at construction,
    # not at the first join
    with pytest.raises(ValueError, match="policy_start='top-level'.*MLPValueHead "
                                         r"\(select_agents\).*'zero'"):  # fmt: skip
        SkillChainingAgent(OptionBank.build(1, 2, order=1), order=1,
                           q_head=MLPValueHead(1, 7), features=nn.Identity(),
                           value_start="max-sample", policy_start="top-level")  # fmt: skip
    with pytest.raises(ValueError, match="'top-level-shifted' reads the linear values"):
        SkillChainingAgent(OptionBank.build(1, 2, order=1), order=2,
                           q_head=MLPQHead(81, 7, 1), features=FourierBasis(4, 2),
                           value_start="max-sample", policy_start="top-level-shifted")


def test_compiled_path_refuses_a_user_head_by_name():
    bank = OptionBank.build(1, 2, order=1)
    agent = HierarchicalAgent(bank, order=1, q_head=ParameterLinearHead(16, 7, 1))
    assert agent.native is False
    from skillchain_torch.backends.hierarchical import AVAILABLE

    if AVAILABLE:
        with pytest.raises(ValueError, match="the top-level head is ParameterLinearHead"):
            HierarchicalAgent(OptionBank.build(1, 2, order=1), order=1, native=True,
                              q_head=ParameterLinearHead(16, 7, 1))  # fmt: skip


def test_the_builtin_head_is_a_value_head():
    head = LinearQHead(3, 6, 1)
    assert missing_methods(head, ValueHead) == []


def test_loss_module_docstring_and_keys():
    assert doctest.testmod(smdp_sarsa_loss, raise_on_error=True).attempted > 0
    loss = smdp_sarsa_loss.SMDPSarsaLoss(LinearQHead(3, 6, 1))
    loss.set_keys(features="decision_phi")
    assert loss.tensor_keys.features == "decision_phi"
    with pytest.raises(ValueError, match="not an accepted tensordict key"):
        loss.set_keys(nope="x")
