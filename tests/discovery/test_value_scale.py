"""A copied option policy moved onto the option's own scale (issue 30, discovery/value_scale)."""

from __future__ import annotations

import torch

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.discovery.value_scale import shift_option_values, target_levels
from skillchain_torch.features import FourierBasis
from skillchain_torch.modules import LinearQHead
from skillchain_torch.options import FourierOptionQHead, OptionBank

F64 = torch.float64


def chain_bank() -> OptionBank:
    bank = OptionBank.build(population=2, slots=2, order=1, capacity=4)
    both = torch.tensor([True, True])
    bank.allocate(both, target_event=0)  # slot 0: the goal
    bank.allocate(both, parent=torch.tensor([0, 0]))  # slot 1: chained to slot 0's set
    return bank


def test_goal_target_is_zero_and_chained_target_is_mean_value_over_parent_positives():
    bank = chain_bank()
    x = torch.tensor([[0.2, 0.5, 0.5, 0.5], [0.6, 0.5, 0.5, 0.5], [0.9, 0.1, 0.5, 0.5]],
                     dtype=F64)  # fmt: skip
    bank.classifier.add_examples(1, 0, x, torch.tensor([True, True, False]))
    basis = FourierBasis(4, 1)
    head = LinearQHead(num_features=basis.num_features, num_decisions=7, population=2)
    head.weight.data[1, 0] = torch.randn(basis.num_features, dtype=F64)
    head.weight.data[1, 3] = torch.randn(basis.num_features, dtype=F64)
    levels = target_levels(bank, head, basis, torch.ones(2, 2, dtype=torch.bool))
    expected = (basis(x[:2]) @ head.weight[1, :5].T).max(-1).values.mean()
    assert levels[:, 0].tolist() == [0.0, 0.0]  # the goal: the episode ends there
    assert levels[0, 1] == 0.0  # agent 0's parent has no positive example
    torch.testing.assert_close(levels[1, 1], expected, rtol=0, atol=1e-12)  # negatives ignored


def test_shift_moves_every_value_by_the_shift_and_keeps_the_policy():
    head = FourierOptionQHead(1, 2, order=2)
    head.weight.data.normal_()
    obs = torch.rand(1, 4, dtype=F64)
    before = head(obs).clone()
    shift = torch.tensor([[0.0, 1234.5]], dtype=F64)
    shift_option_values(head, torch.tensor([[False, True]]), shift)
    after = head(obs)
    torch.testing.assert_close(after[0, 0], before[0, 0], rtol=0, atol=0)
    torch.testing.assert_close(after[0, 1] - before[0, 1], torch.full((5,), 1234.5, dtype=F64),
                               rtol=0, atol=1e-9)  # fmt: skip
    assert after[0, 1].argmax() == before[0, 1].argmax()


def test_agent_accepts_the_shifted_start_and_passes_its_completion_reward():
    agent = SkillChainingAgent.build(population=1, policy_start="top-level-shifted",
                                     completion_reward=500.0)  # fmt: skip
    assert agent.discovery.policy_start == "top-level-shifted"
    assert agent.discovery.completion_reward == 500.0
