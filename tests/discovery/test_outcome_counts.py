"""How option executions end, counted per agent-episode (SkillChaining.outcomes, written as a
run's option_outcomes.npy): success, timeout, episode end; a truncated one is not counted."""

from __future__ import annotations

import torch

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.discovery.skill_chaining import OUTCOMES


def test_outcomes_by_kind():
    agent = SkillChainingAgent.build(population=4, slots=2, seed=0)
    discovery = agent.discovery
    discovery.bank.allocate(torch.ones(4, dtype=torch.bool), target_event=0)
    option = torch.tensor([0, 0, 0, 0])
    reached = torch.tensor([[True, False], [False, False], [False, False], [False, False]])
    duration = torch.tensor([7, 250, 30, 30])
    ended = torch.ones(4, dtype=torch.bool)
    terminated = torch.tensor([False, False, True, False])  # row 3: truncated
    discovery._finish_executions(option, reached, duration, ended, terminated)
    assert OUTCOMES == ("success", "timeout", "episode_end")
    counts = discovery.counts
    assert counts.outcomes[:, 0].tolist() == [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]]
    assert counts.steps[:, 0].tolist() == [7, 250, 30, 30]  # a truncated one's steps count
    state = discovery.state_dict()
    counts.outcomes.zero_()
    discovery.load_state_dict(state)
    assert int(discovery.counts.outcomes.sum()) == 3
    discovery.end_episodes(torch.tensor([True, False, False, False]), agent.q_head)
    assert discovery.counts.last_outcomes[0, 0].tolist() == [1, 0, 0]
    assert int(discovery.counts.outcomes[0].sum()) == 0 and int(counts.steps[1, 0]) == 250
