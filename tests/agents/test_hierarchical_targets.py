"""HierarchicalAgent.targets: OptionBank.target_reached's answer, computed the cheap way."""

from __future__ import annotations

import pytest
import torch

from skillchain_torch.agents import HierarchicalAgent
from skillchain_torch.backends.select import same_bits_kernels
from skillchain_torch.options import GoalEvent, OptionBank, OptionStatus, RegionEvent

F64 = torch.float64
EVENTS = (GoalEvent(), RegionEvent((0.9, 0.9), 0.1))


def random_bank(P=40, K=5, seed=0) -> OptionBank:
    """Empty, base-event (goal or region, or none) and chained slots of every status."""
    g = torch.Generator().manual_seed(seed)
    bank = OptionBank.build(P, K, order=1)
    bank.status.copy_(torch.randint(0, 4, (P, K), generator=g))
    bank.target_event.copy_(torch.randint(-1, len(EVENTS), (P, K), generator=g))
    chained = torch.rand(P, K, generator=g) < 0.4
    bank.parent.copy_(torch.where(chained, torch.randint(0, K, (P, K), generator=g), -1))
    with torch.no_grad():
        bank.classifier.weight.normal_(generator=g)
        bank.classifier.bias.normal_(generator=g)
    bank.classifier.trained.fill_(True)
    return bank


@pytest.mark.parametrize("native", [True, False])
def test_targets_equal_target_reached(native):
    bank = random_bank()
    with same_bits_kernels(native):  # the agent takes discovery's compiled twins, or not
        agent = HierarchicalAgent(bank, order=1, events=EVENTS)
    g = torch.Generator().manual_seed(1)
    obs = torch.rand(40, 4, dtype=F64, generator=g)
    obs[:10, :2] = 0.9  # inside the region
    terminated = torch.rand(40, generator=g) < 0.3
    contains = bank.classifier.contains(obs)
    got = agent.targets(obs, terminated, contains)
    expected = bank.target_reached(obs, terminated, EVENTS, contains=contains)
    assert torch.equal(got, expected)
    assert bool(expected.any()) and not bool(expected.all())  # exercised both ways


def test_targets_refuse_an_event_the_agent_lacks():
    """Refused when the bank arrives (at construction), not in the step."""
    bank = random_bank()
    bank.target_event[0, 0], bank.status[0, 0] = 2, int(OptionStatus.LEARNED)
    with pytest.raises(ValueError, match="target event 2 used by a slot, but only 2 given"):
        HierarchicalAgent(bank, order=1, events=EVENTS)
