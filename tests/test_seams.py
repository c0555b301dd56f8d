"""The trainer's two seams, declared in ``skillchain_torch.interfaces``: every built-in agent and
env stepper satisfies them, and an agent written from the protocol alone (no library base class)
trains under the trainer."""

import numpy as np
import pytest
import torch

from skillchain_torch.interfaces import EnvStepper, EpisodeAgent, missing_methods


def built_in_agents():
    from skillchain_torch.agents import FlatSarsaAgent, HierarchicalAgent, SkillChainingAgent
    from skillchain_torch.options import OptionBank
    from skillchain_torch.trainers import TrainConfig

    yield FlatSarsaAgent(TrainConfig(runs=2, episodes=1, order=1))
    yield HierarchicalAgent(OptionBank.build(population=2, slots=2, order=1), order=1)
    yield SkillChainingAgent.build(population=2, slots=2, order=1)


@pytest.mark.parametrize("agent", list(built_in_agents()), ids=type)
def test_built_in_agents_follow_the_episode_protocol(agent):
    assert isinstance(agent, EpisodeAgent), missing_methods(agent, EpisodeAgent)


def test_both_steppers_follow_the_stepper_protocol():
    from skillchain_torch.envs.pinball import PinballEnv
    from skillchain_torch.envs.pinball.stepper import ActiveEnvStepper
    from skillchain_torch.trainers.env_stepper import EnvStepper as TorchRLEnvStepper

    stepper = ActiveEnvStepper(PinballEnv("pinball_box", batch_size=[2], seed=0))
    assert isinstance(stepper, EnvStepper), missing_methods(stepper, EnvStepper)
    for name in ("start", "step", "reset", "compact", "sync", "state_dict", "load_state_dict"):
        assert callable(getattr(TorchRLEnvStepper, name))


def test_an_object_is_not_an_agent():
    assert not isinstance(object(), EpisodeAgent)
    assert "observe_ends" in missing_methods(object(), EpisodeAgent)


class RandomAgent:
    """An agent from the protocol alone: uniform random actions, its own stream per agent."""

    def __init__(self, population: int, seed: int = 0):
        self.population = population
        self._index = torch.arange(population)
        self._rng = [torch.Generator().manual_seed(seed + p) for p in range(population)]
        self._action = torch.zeros(population, dtype=torch.int64)

    def _draw(self) -> torch.Tensor:
        for p in self._index.tolist():
            self._action[p] = int(torch.randint(5, (1,), generator=self._rng[p]))
        return self.actions

    def begin(self, obs):
        return self._draw()

    def observe(self, obs, reward):
        return self._draw()

    def observe_ends(self, obs, reward, terminated, truncated, restart_rows, start_obs):
        return self._draw()

    def compact(self, keep):
        self._index = self._index[keep]

    @property
    def actions(self):
        return self._action[self._index]

    @property
    def index(self):
        return self._index

    def flush(self):
        pass

    def state_dict(self):
        return {"index": self._index.clone(), "action": self._action.clone()}

    def load_state_dict(self, state):
        self._index, self._action = state["index"], state["action"]


def test_an_agent_from_the_protocol_alone_trains(tmp_path):
    from skillchain_torch.trainers import TrainConfig
    from skillchain_torch.trainers.population import PopulationTrainer

    agent = RandomAgent(population=2)
    assert isinstance(agent, EpisodeAgent)
    config = TrainConfig(runs=2, episodes=2, map="pinball_box", seed=0, max_episode_steps=50)
    trainer = PopulationTrainer(config, out_dir=tmp_path, agent=agent).train()
    returns = np.asarray(trainer.returns)
    assert returns.shape == (2, 2) and np.isfinite(returns).all()
