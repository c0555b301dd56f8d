"""Goals that mean success (issue 53): the goal by name or as the user's function of the
transition, each env's own, and CartPole (termination is failure) refused for skill chaining."""

from __future__ import annotations

import pytest
import torch
from corridor import CORRIDOR, NO, YES, R, make_agent, point

from skillchain_torch.options import GoalEvent, TransitionGoal, env_goal, goal_event
from skillchain_torch.options.goals import goal_note
from skillchain_torch.trainers import TrainConfig
from skillchain_torch.trainers.config.checks import check_values
from skillchain_torch.trainers.config.config import ConfigError


def obs(n: int) -> torch.Tensor:
    return torch.zeros(n, 4, dtype=torch.float64)


def test_goal_names_build_their_events():
    assert isinstance(goal_event(None), GoalEvent) and isinstance(goal_event("terminated"),
                                                                   GoalEvent)  # fmt: skip
    positive = goal_event("terminated-positive")
    fired = positive(obs(4), torch.tensor([True, True, False, False]),
                     torch.tensor([100.0, -100.0, 1.0, -1.0], dtype=torch.float64))
    assert fired.tolist() == [True, False, False, False]  # only where the episode terminated
    own = goal_event("skillchain_torch.options.goals:_terminated_positive")
    assert isinstance(own, TransitionGoal)


@pytest.mark.parametrize("spec, message", [
    ("landed", "expected one of terminated, terminated-positive or MODULE:FUNCTION"),
    ("no_such_module_xyz:f", "cannot import f from no_such_module_xyz"),
    ("os:sep", "sep is not callable"),
])
def test_a_bad_goal_is_one_line(spec, message):
    with pytest.raises(ValueError, match=message):
        goal_event(spec)


def test_a_goal_function_must_return_one_bool_per_agent():
    goal = TransitionGoal(lambda td: td["reward"], name="bad")
    with pytest.raises(ValueError, match=r"goal 'bad' must return a BoolTensor \[2\]"):
        goal(obs(2), torch.tensor([True, False]), torch.zeros(2, dtype=torch.float64))


def test_each_env_names_its_goal():
    assert env_goal(None) == "terminated"  # Pinball: the hole
    assert env_goal("gymnasium:MountainCar-v0") == "terminated"
    assert env_goal("gymnasium:Acrobot-v1") == "terminated"
    assert env_goal("gymnasium:LunarLander-v3") == "terminated-positive"
    assert env_goal("gymnasium:CartPole-v1") is None
    assert env_goal("gymnasium:my_pkg:Thing-v0") == "terminated"  # unknown: its own flag
    note = goal_note("gymnasium:my_pkg:Thing-v0")
    assert "'terminated'" in note and "--goal" in note and "\n" not in note
    assert goal_note("gymnasium:MountainCar-v0") is None and goal_note(None) is None


def test_cartpole_refuses_skill_chaining_without_a_goal():
    config = TrainConfig(agent="skill-chaining", env="gymnasium:CartPole-v1", runs=1)
    with pytest.raises(ConfigError, match="terminates only in failure.*--goal MODULE:FUNCTION"):
        check_values(config)
    check_values(TrainConfig(agent="flat", env="gymnasium:CartPole-v1", runs=1))  # flat: fine
    check_values(TrainConfig(agent="skill-chaining", env="gymnasium:CartPole-v1", runs=1,
                             goal="skillchain_torch.options.goals:_terminated_positive"))
    with pytest.raises(ConfigError, match="goal 'nope'"):
        check_values(TrainConfig(agent="skill-chaining", runs=1, goal="nope"))


def walk(agent, end_reward: float, first: bool = False) -> None:
    """The corridor, rewards -1, its last step terminating with ``end_reward``."""
    if first:
        agent.begin(point(CORRIDOR[0]))
    for x in CORRIDOR[1:-1]:
        agent.observe(point(x), R)
    agent.observe_ends(point(CORRIDOR[-1]), torch.tensor([end_reward], dtype=torch.float64),
                       YES, NO, torch.tensor([0]), point(0.1))  # fmt: skip


def test_a_termination_that_is_not_the_goal_creates_no_goal_option():
    # The goal "terminated with a positive reward": an episode that terminates with reward
    # -100 (a crash) creates nothing; one ending with +100 creates the goal option.
    agent = make_agent(events=(goal_event("terminated-positive"),))
    walk(agent, -100.0, first=True)
    assert agent.bank.live()[0].sum() == 0
    walk(agent, 100.0)
    assert agent.bank.live()[0].sum() == 1
    assert agent.discovery.target_name(0, 0) == "goal"


def test_build_takes_the_goal_by_name():
    from skillchain_torch.agents import SkillChainingAgent

    agent = SkillChainingAgent.build(1, order=1, goal="terminated-positive")
    assert len(agent.events) == 1 and isinstance(agent.events[0], TransitionGoal)
    with pytest.raises(ValueError, match="not both"):
        SkillChainingAgent.build(1, order=1, goal="terminated", events=(GoalEvent(),))
