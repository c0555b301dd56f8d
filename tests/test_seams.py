"""The trainer's two seams, declared in ``skillchain_torch.interfaces``: every built-in agent and
env stepper satisfies them, and an agent written from the protocol alone (no library base class)
trains under the trainer; and each of the five pieces written from its protocol alone works."""

import numpy as np
import pytest
import torch

from skillchain_torch.interfaces import EnvStepper, EpisodeAgent, missing_methods
from skillchain_torch.options.q_head import OptionQHead


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


# ------------------------------------------------------------------ the other three pieces
class RightHalf:
    """A target event from the TerminationPredicate protocol alone: the ball in the right half."""

    name = "right half"

    def __call__(self, obs, terminated=None):
        return obs[:, 0] > 0.5


def test_a_termination_predicate_from_the_protocol_alone_is_a_target(tmp_path):
    """A predicate of the user's own is a base target event (section 4.4: add any indicator):
    discovery creates options aimed at it, and the option tree names it."""
    from skillchain_torch.agents import SkillChainingAgent
    from skillchain_torch.interfaces import TerminationPredicate
    from skillchain_torch.options import GoalEvent
    from skillchain_torch.trainers import TrainConfig
    from skillchain_torch.trainers.loop.population import PopulationTrainer

    assert isinstance(RightHalf(), TerminationPredicate)
    agent = SkillChainingAgent.build(2, order=1, gestation=1, slots=4,
                                     events=(GoalEvent(), RightHalf()))  # fmt: skip
    config = TrainConfig(runs=2, episodes=3, map="pinball_box", agent="skill-chaining",
                         max_episode_steps=300)
    PopulationTrainer(config, out_dir=tmp_path, agent=agent).train()
    live = agent.bank.live()
    targets = {agent.discovery.target_name(p, k) for p, k in live.nonzero().tolist()}
    assert "right half" in targets, targets


class TableHead(torch.nn.Module):
    """A top-level value head from the ValueHead protocol alone (no LinearQHead): one weight
    per agent, decision and feature, trained by autograd."""

    def __init__(self, population, num_features, num_decisions):
        super().__init__()
        self.population, self.num_features = population, num_features
        self.num_decisions = num_decisions
        self.weight = torch.nn.Parameter(torch.zeros(population, num_decisions, num_features,
                                                     dtype=torch.float64))  # fmt: skip

    def forward(self, phi):
        return torch.einsum("pdf,pf->pd", self.weight, phi)

    def forward_mask(self, phi, mask, dense=0):
        return torch.where(mask, self(phi), torch.zeros((), dtype=phi.dtype))

    def q_value(self, phi, decision, index=None):
        q = self(phi).gather(1, decision[:, None])[:, 0]
        return q if index is None else q[index]

    def set_values(self, mask, value):
        with torch.no_grad():
            self.weight[..., 0] = torch.where(mask, value.to(self.weight.dtype),
                                              self.weight[..., 0])  # fmt: skip
            self.weight[..., 1:] = torch.where(mask[..., None], 0.0, self.weight[..., 1:])


class PlainTD:
    """A learner from the Learner protocol alone: one SGD step on the SMDP Sarsa error,
    ``td -> td_error [P]``, written without the library's loss modules."""

    def __init__(self, head, lr=1e-3):
        self.head, self.calls = head, 0
        self.optimizer = torch.optim.SGD(head.parameters(), lr=lr)

    def __call__(self, td):
        self.calls += 1
        q = self.head.q_value(td["phi"], td["decision"])
        target = td["decision_return"] + torch.where(td["terminated"], 0.0, td["next_value"])
        error = torch.where(td["active"], target.detach() - q, 0.0)
        self.optimizer.zero_grad()
        (0.5 * error.pow(2)).sum().backward()
        self.optimizer.step()
        return error.detach()


def test_a_value_head_and_learner_from_the_protocols_alone_train(tmp_path):
    """A top-level head and a learner of the user's own, neither a library class: the agent
    takes the torch path, the learner is called at every decision, the head's weights move."""
    from skillchain_torch.agents import SkillChainingAgent
    from skillchain_torch.features import FourierBasis
    from skillchain_torch.interfaces import Learner, ValueHead
    from skillchain_torch.options import FourierOptionQHead, InitiationClassifier, OptionBank
    from skillchain_torch.trainers import TrainConfig
    from skillchain_torch.trainers.loop.population import PopulationTrainer

    basis = FourierBasis(4, 1)
    head = TableHead(2, basis.num_features, 5 + 4)
    learner = PlainTD(head)
    assert isinstance(head, ValueHead) and isinstance(learner, Learner)
    bank = OptionBank(2, 4, FourierOptionQHead(2, 4, order=1),
                      InitiationClassifier(2, 4, capacity=64))  # fmt: skip
    agent = SkillChainingAgent(bank, q_head=head, features=basis, top_learner=learner,
                               gestation=1)  # fmt: skip
    assert not agent.native  # a user's head takes the torch path
    config = TrainConfig(runs=2, episodes=3, map="pinball_box", agent="skill-chaining",
                         max_episode_steps=300)
    PopulationTrainer(config, out_dir=tmp_path, agent=agent).train()
    assert learner.calls > 0 and bool(head.weight.detach().abs().sum() > 0)


class RawOptionHead(OptionQHead):
    """An option head from the OptionHead interface alone (not FourierOptionQHead): linear in
    the raw observation and a bias, Q-learning by hand."""

    def __init__(self, population, slots, num_actions=5, alpha=0.01):
        super().__init__()
        self.population, self.slots, self.num_actions, self.alpha = (population, slots,
                                                                     num_actions, alpha)
        self.config = {"alpha": alpha}
        self.register_buffer("weight", torch.zeros(population, slots, num_actions, 5,
                                                   dtype=torch.float64))  # fmt: skip

    def _x(self, obs):
        return torch.cat([torch.ones_like(obs[:, :1]), obs], dim=1)  # [P, 5]

    def forward(self, obs):
        return torch.einsum("pkaf,pf->pka", self.weight, self._x(obs))

    def td_update(self, obs, action, target, mask):
        x, a = self._x(obs), action[:, None].expand(-1, self.slots)  # one action, every slot
        q = self(obs).gather(2, a[..., None])[..., 0]  # [P, K]
        error = torch.where(mask, target - q, 0.0)
        step = self.alpha * error[..., None] * x[:, None, :]  # [P, K, 5]
        self.weight.scatter_add_(2, a[..., None, None].expand(-1, -1, 1, 5), step[:, :, None])
        return error

    def reset_slots(self, mask):
        self.weight[mask] = 0.0

    def select_agents(self, index, seeds=None):
        head = RawOptionHead(len(index), self.slots, self.num_actions, self.alpha)
        head.weight.copy_(self.weight[torch.as_tensor(index)])
        return head

    def slot_tensors(self):
        return {"weight": self.weight}


def test_an_option_head_from_the_interface_alone_learns_under_skill_chaining(tmp_path):
    """An option head of the user's own (the OptionQHead interface, not the Fourier head):
    options are created and their values learn through its td_update."""
    from skillchain_torch.agents import SkillChainingAgent
    from skillchain_torch.options import InitiationClassifier, OptionBank
    from skillchain_torch.trainers import TrainConfig
    from skillchain_torch.trainers.loop.population import PopulationTrainer

    head = RawOptionHead(2, 4)
    bank = OptionBank(2, 4, head, InitiationClassifier(2, 4, capacity=64))
    agent = SkillChainingAgent(bank, order=1, gestation=1)
    assert not agent.native  # a user's option head takes the torch path
    config = TrainConfig(runs=2, episodes=4, map="pinball_box", agent="skill-chaining",
                         max_episode_steps=300)
    PopulationTrainer(config, out_dir=tmp_path, agent=agent).train()
    assert int(bank.live().sum()) > 0 and bool(head.weight.abs().sum() > 0)
