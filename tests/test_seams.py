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
    from skillchain_torch.trainers.loop.env_stepper import EnvStepper as TorchRLEnvStepper

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
    from skillchain_torch.trainers.loop.population import PopulationTrainer

    agent = RandomAgent(population=2)
    assert isinstance(agent, EpisodeAgent)
    config = TrainConfig(runs=2, episodes=2, map="pinball_box", seed=0, max_episode_steps=50)
    trainer = PopulationTrainer(config, out_dir=tmp_path, agent=agent).train()
    returns = np.asarray(trainer.returns)
    assert returns.shape == (2, 2) and np.isfinite(returns).all()


class DelegatingSet(torch.nn.Module):
    """An initiation set from the protocol alone (no library base class besides ``nn.Module``):
    it owns a logistic classifier and answers every declared method through it."""

    def __init__(self, population, slots, **kwargs):
        super().__init__()
        from skillchain_torch.options import InitiationClassifier

        self.inner = InitiationClassifier(population, slots, **kwargs)
        self.population, self.slots, self.config = population, slots, dict(self.inner.config)

    @property
    def trained(self):
        return self.inner.trained

    def logit(self, obs):
        return self.inner.logit(obs)

    def contains(self, obs):
        return self.inner.contains(obs)

    def contains_points(self, agent, slot, obs):
        return self.inner.contains_points(agent, slot, obs)

    def add_examples(self, agents, slots, obs, labels):
        return self.inner.add_examples(agents, slots, obs, labels)

    def stored_classes(self):
        return self.inner.stored_classes()

    def has_both_classes(self):
        return self.inner.has_both_classes()

    def fit(self, mask=None):
        return self.inner.fit(mask)

    def constrain(self, mask):
        self.inner.constrain(mask)

    def reset_slots(self, mask):
        self.inner.reset_slots(mask)

    def snapshot(self):
        return self.inner.snapshot()

    def weight_change(self, before, after=None):
        return self.inner.weight_change(before, after)

    def select_agents(self, index, seeds=None):
        raise NotImplementedError("not needed to train")


def test_an_initiation_set_from_the_protocol_alone_learns_under_skill_chaining(tmp_path):
    """Issue 51: a class implementing InitiationSet without subclassing InitiationClassifier used
    to fail on ``seeds``, ``examples``, ``native`` and ``lr`` (an ``OptionBank`` without
    ``obs_dim``); now discovery stores its examples and fits it, and the trainer checks it."""
    from skillchain_torch.agents import SkillChainingAgent
    from skillchain_torch.interfaces import InitiationSet
    from skillchain_torch.options import FourierOptionQHead, OptionBank
    from skillchain_torch.trainers import TrainConfig
    from skillchain_torch.trainers.loop.population import PopulationTrainer

    sets = DelegatingSet(2, 4, capacity=64)
    assert isinstance(sets, InitiationSet), missing_methods(sets, InitiationSet)
    bank = OptionBank(2, 4, FourierOptionQHead(2, 4, order=1), sets)
    assert bank.obs_dim == 4
    agent = SkillChainingAgent(bank, order=2, gestation=1)
    config = TrainConfig(runs=2, episodes=12, map="pinball_box", agent="skill-chaining",
                         max_episode_steps=300)
    PopulationTrainer(config, out_dir=tmp_path, agent=agent).train()
    assert int(bank.live().sum()) > 0  # discovery created options with it
    assert int(sets.inner.count.sum()) > 0 and bool(sets.trained.any())  # examples, fits
    assert (tmp_path / "checkpoints").is_dir()
