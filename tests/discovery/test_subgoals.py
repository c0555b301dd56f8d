"""Issue 52's control (b), random subgoals: discs drawn per agent over free space, base
events in place of the chain, listed at the moments chaining would add a target."""

from __future__ import annotations

import pytest
import torch
from corridor import END, R, make_agent, point
from test_chaining import learned_goal_option

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.discovery.subgoals import SUBGOAL_RADIUS, random_subgoals
from skillchain_torch.envs.pinball.geometry import point_in_polygon
from skillchain_torch.envs.pinball.maps import load_map
from skillchain_torch.options import GoalEvent, RegionEvent


def test_centres_are_each_agents_own_and_outside_the_obstacles():
    events = random_subgoals(population=4, count=6, seed=10, map="pinball_simple_single")
    centres = torch.stack([e.center for e in events], dim=1)  # [P, 6, 2]
    for p in range(4):  # agent 10 + p alone draws the discs it draws in the population
        alone = random_subgoals(population=1, count=6, seed=10 + p, map="pinball_simple_single")
        assert torch.equal(torch.stack([e.center for e in alone], dim=1)[0], centres[p])
    assert not torch.equal(centres[0], centres[1])  # agents differ
    polygons = [poly.tolist() for poly in load_map("pinball_simple_single").polygons]
    for x, y in centres.reshape(-1, 2).tolist():
        assert 0 <= x < 1 and 0 <= y < 1
        assert not any(point_in_polygon(x, y, poly) for poly in polygons)
    assert all(e.radius == SUBGOAL_RADIUS for e in events)


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="count >= 0 and radius > 0"):
        random_subgoals(population=1, count=2, seed=0, radius=0.0)
    with pytest.raises(ValueError, match="need 3 seeds"):
        random_subgoals(population=3, count=2, seed=torch.tensor([1, 2]))


def test_region_event_select_agents_keeps_the_rows_centres():
    event = RegionEvent(torch.tensor([[0.1, 0.1], [0.9, 0.9]]), 0.05)
    picked = event.select_agents([1, 1, 0])
    obs = torch.tensor([[0.9, 0.9, 0, 0], [0.1, 0.1, 0, 0], [0.1, 0.1, 0, 0]], dtype=torch.float64)
    assert picked(obs).tolist() == [True, False, True]
    shared = RegionEvent((0.5, 0.5), 0.1)
    assert torch.equal(shared.select_agents([0, 0]).center, shared.center)


def test_build_random_subgoals_makes_the_goal_and_one_disc_per_other_slot():
    agent = SkillChainingAgent.build(3, subgoals="random", slots=5, order=1,
                                     map="pinball_simple_single")  # fmt: skip
    names = [e.name for e in agent.events]
    assert names == ["goal", "subgoal 1", "subgoal 2", "subgoal 3", "subgoal 4"]
    assert isinstance(agent.events[0], GoalEvent) and not agent.discovery.chaining
    with pytest.raises(ValueError, match="subgoals must be one of chained, random"):
        SkillChainingAgent.build(1, subgoals="nearby", order=1)
    with pytest.raises(ValueError, match="draws its own events"):
        SkillChainingAgent.build(1, subgoals="random", order=1, events=(GoalEvent(),))


def test_without_chaining_a_learned_set_is_no_target_but_lists_the_next_base_event():
    # The corridor's chaining test, with chaining off: entering the goal option's learned set
    # creates nothing, while base event 1 ("end", near x = 0.9) is listed now that one set is
    # learned, and creates an option aimed at it.
    agent = make_agent(events=(GoalEvent(), END), chaining=False)
    learned_goal_option(agent)
    agent.begin(point(0.1))
    agent.observe(point(0.5), R)
    agent.observe(point(0.75), R)  # into the learned set (x > 0.6): no child
    assert agent.bank.live()[0].sum() == 1
    agent.observe(point(0.9), R)  # into "end": listed after one learned set
    assert agent.bank.live()[0].sum() == 2
    assert agent.bank.parent[0, 1] == -1 and agent.discovery.target_name(0, 1) == "end"


def test_without_chaining_base_events_wait_for_learned_sets():
    # No learned set yet: "end" is not listed, so entering it creates nothing.
    agent = make_agent(events=(GoalEvent(), END), chaining=False)
    agent.begin(point(0.1))
    agent.observe(point(0.5), R)
    agent.observe(point(0.9), R)
    assert agent.bank.live()[0].sum() == 0
