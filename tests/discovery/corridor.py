"""The corridor on which skill chaining's rules are tested by hand (tests/discovery).

The agent is driven along a one-dimensional *corridor*: observations ``(x, 0.5, 0.5, 0.5)``
with ``x`` chosen by the test, whatever the agent does, so every rule is checked where it
should fire and where it should not. Initiation sets are set by hand as half-planes in ``x``
(feature 1 of the polynomial features is ``x``); the goal is the environment's ``terminated``
flag and ``END`` is a hand-set region event near ``x = 0.9``.

Example:
    >>> agent = make_agent()
    >>> episode(agent, CORRIDOR, terminated=True, first=True)
    >>> [e.kind for e in agent.discovery.log]
    ['created']
"""

from __future__ import annotations

import torch

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.options import GoalEvent, OptionStatus, RegionEvent

F64 = torch.float64
END = RegionEvent(center=(0.9, 0.5), radius=0.05, name="end")
YES, NO = torch.tensor([True]), torch.tensor([False])
R = torch.tensor([-1.0], dtype=F64)


def point(x: float) -> torch.Tensor:
    return torch.tensor([[x, 0.5, 0.5, 0.5]], dtype=F64)


GOAL_ONLY = (GoalEvent(),)


def make_agent(slots=3, events=GOAL_ONLY, **kwargs) -> SkillChainingAgent:
    """One agent of the paper's preset (the rules under test are the paper's), order-1
    features, no exploration and a frozen top level (alpha 0)."""
    kwargs = {"order": 1, "option_order": 1, "alpha": 0.0, "epsilon": 0.0,
              "option_epsilon": 0.0, "events": events, **kwargs}
    return SkillChainingAgent.build(population=1, preset="paper", slots=slots, **kwargs)


def episode(agent, xs, terminated=True, first=False, next_start=0.1):
    """Walk the corridor through ``xs``; the last step terminates (goal) or truncates."""
    if first:
        agent.begin(point(xs[0]))
    for x in xs[1:-1]:
        agent.observe(point(x), R)
    end = YES if terminated else NO
    agent.observe_ends(point(xs[-1]), R, end, ~end, torch.tensor([0]), point(next_start))


def half_plane(agent, slot, threshold, above=True):
    """Slot ``slot``'s classifier says ``x > threshold`` (or ``<``), trained."""
    clf = agent.bank.classifier
    sign = 1.0 if above else -1.0
    with torch.no_grad():
        clf.weight[:, slot] = 0.0
        clf.weight[:, slot, 1] = sign
        clf.bias[:, slot] = -threshold * sign
        clf.trained[:, slot] = True


def add_option(agent, target_event=-1, parent=-1, status=OptionStatus.LEARNING, episode=0):
    slot = agent.bank.allocate(YES, target_event=target_event, parent=parent, episode=episode)
    agent.bank.set_status(torch.nn.functional.one_hot(slot, agent.bank.slots).bool(), status)
    agent.discovery._exclusion = None  # the bank changed behind the agent's back
    return int(slot)


def prefer_option(agent, slot, value=1e6):
    agent.q_head.weight[:, 5 + slot, :] = 0.0
    agent.q_head.weight[:, 5 + slot, 0] = value


CORRIDOR = [0.1, 0.3, 0.5, 0.7, 0.9]
