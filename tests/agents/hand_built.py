"""Hand-built options and agents for the HierarchicalAgent tests: half-plane initiation sets
on x, a target region at the goal, Q values set by hand.

Example:
    >>> agent = make_agent(make_bank())
    >>> prefer_option(agent)
    >>> actions = agent.begin(obs((0.7, 0.5, 0.5, 0.5)))
    >>> agent.options.tolist(), agent.decisions.tolist()
    ([0], [5])
"""

from __future__ import annotations

import torch

from skillchain_torch.agents import HierarchicalAgent
from skillchain_torch.options import (
    FourierOptionQHead,
    InitiationClassifier,
    OptionBank,
    OptionStatus,
    RegionEvent,
)

F64 = torch.float64
TARGET = (0.9, 0.2)
REGION = RegionEvent(center=TARGET, radius=0.05, name="target region")


def obs(*rows) -> torch.Tensor:
    return torch.tensor([list(r) for r in rows], dtype=F64)


def half_plane(classifier: InitiationClassifier, slot: int, sign: float) -> None:
    """Slot ``slot``'s initiation set: ``x > 0.5`` (sign +1) or ``x < 0.5`` (sign -1)."""
    with torch.no_grad():
        classifier.weight[:, slot] = 0.0
        classifier.weight[:, slot, 1] = sign  # feature 1 is x (PolynomialFeatures order)
        classifier.bias[:, slot] = -0.5 * sign
        classifier.trained[:, slot] = True


def make_bank(population=1, slots=1, signs=(1.0,), order=1, q_head=None, seed=0):
    q_head = q_head or FourierOptionQHead(population, slots, order=order)
    bank = OptionBank(population, slots, q_head,
                      InitiationClassifier(population, slots, seed=seed))
    for k, sign in enumerate(signs):
        half_plane(bank.classifier, k, sign)
    bank.status[:] = int(OptionStatus.LEARNED)
    bank.target_event[:] = 0
    return bank


def make_agent(bank, **kwargs) -> HierarchicalAgent:
    kwargs = {"order": 1, "alpha": 0.01, "epsilon": 0.0, "option_epsilon": 0.0,
              "events": (REGION,), **kwargs}
    return HierarchicalAgent(bank, **kwargs)


def prefer_option(agent: HierarchicalAgent, slot: int = 0, value: float = 100.0) -> None:
    """Make Q(s, option) = ``value`` everywhere (feature 0 is the constant cosine)."""
    agent.q_head.weight[:, 5 + slot, 0] = value


NO = torch.tensor([False])
