"""HierarchicalCollector: keys, shapes and option annotations of the transition batches."""

from __future__ import annotations

import torch

from skillchain_torch.agents import HierarchicalAgent
from skillchain_torch.collectors import HierarchicalCollector
from skillchain_torch.envs.pinball import PinballEnv, observation
from skillchain_torch.options import (
    FourierOptionQHead,
    InitiationClassifier,
    OptionBank,
    OptionStatus,
    RegionEvent,
)


def make(population=2, seed=0, max_episode_steps=30):
    bank = OptionBank(population, 1, FourierOptionQHead(population, 1, order=1),
                      InitiationClassifier(population, 1, seed=seed))
    bank.status[:] = int(OptionStatus.LEARNED)  # untrained classifier: available everywhere
    bank.target_event[:] = 0
    agent = HierarchicalAgent(bank, order=1, epsilon=0.3, seed=seed,
                              events=(RegionEvent(center=(0.5, 0.5), radius=0.1),),
                              max_option_steps=10)
    env = PinballEnv("pinball_simple_single", batch_size=[population], seed=seed,
                     max_episode_steps=max_episode_steps)
    return env, agent


def test_batches_keys_and_shapes():
    env, agent = make()
    collector = HierarchicalCollector(env, agent, frames_per_batch=41, total_frames=120)
    batches = list(collector)
    assert len(batches) == 3 and collector.frames_per_batch == 40
    td = batches[0]
    assert td.batch_size == (20, 2)
    for key in ("observation", "state"):
        assert td[key].shape == (20, 2, 4) and td["next", key].shape == (20, 2, 4)
    for key in ("action", "decision", "option"):
        assert td[key].dtype == torch.int64 and td[key].shape == (20, 2)
    for key in ("reward", "done", "terminated", "truncated"):
        assert td["next", key].shape == (20, 2, 1)
    torch.testing.assert_close(td["observation"], observation(td["state"]), rtol=0, atol=0)


def test_option_annotations_and_restarts():
    env, agent = make(max_episode_steps=30)
    td = HierarchicalCollector(env, agent, frames_per_batch=200).rollout()
    option, decision, action = td["option"], td["decision"], td["action"]
    executing = option >= 0
    assert bool(executing.any()) and bool((~executing).any())
    assert torch.equal(decision[executing], 5 + option[executing])
    assert torch.equal(decision[~executing], action[~executing])  # a primitive decision
    assert bool((action < 5).all())
    done = td["next", "done"][..., 0]
    assert done.sum().item() == 6  # 100 steps, episodes of 30: 3 truncations per env
    # next state of a step is the next step's state, except where the episode restarted
    same = torch.equal(td["next", "state"][:-1][~done[:-1]], td["state"][1:][~done[:-1]])
    assert same
    start = td["state"][1:][done[:-1]]
    assert torch.equal(start[:, 2:], torch.zeros_like(start[:, 2:]))  # restarts at rest
    # an option lasts at most max_option_steps = 10 consecutive steps in one decision
    assert int(agent.duration.max()) <= 10


def test_doctests():
    import doctest

    from skillchain_torch import interfaces
    from skillchain_torch.collectors import hierarchical

    for module in (hierarchical, interfaces):
        assert doctest.testmod(module).attempted > 0
        assert doctest.testmod(module).failed == 0


def test_trainer_mode_batches_end_where_episodes_end_and_retire_agents():
    """``frames_per_batch=None`` and an episode budget (what the trainer runs): every batch
    ends at a step in which an episode ended, its rows never change inside it, its returns and
    step counts add up, and the collector stops once every agent has run its episodes."""
    env, agent = make(population=2, max_episode_steps=30)
    collector = HierarchicalCollector(env, agent, episodes=2, state=False)
    batches = list(collector)
    assert collector.finished and collector.episodes_done.tolist() == [2, 2]
    ends = 0
    for td in batches:
        done = td["next", "done"][..., 0]
        assert bool(done[-1].any()) and not bool(done[:-1].any())
        assert torch.equal(td["agent"], td["agent"][:1].expand_as(td["agent"]))
        ended = done[-1]
        ends += int(ended.sum())
        steps = td["next", "step_count"][-1, ended, 0]
        assert bool((steps == 30).all())  # truncated at 30 steps, counted from its start
    assert ends == 4 and "state" not in td.keys()


class CountingAgent:
    """A protocol-only agent (no declared step state) that delegates to a built-in one and
    counts what the collector asks of it."""

    def __init__(self, agent):
        import collections

        self.inner, self.calls, self.population = agent, collections.Counter(), agent.population

    def _count(self, name):
        self.calls[name] += 1
        return getattr(self.inner, name)

    def begin(self, obs):
        return self._count("begin")(obs)

    def observe(self, obs, reward):
        return self._count("observe")(obs, reward)

    def observe_ends(self, *args):
        return self._count("observe_ends")(*args)

    def compact(self, keep):
        return self._count("compact")(keep)

    @property
    def actions(self):
        return self._count("actions")

    @property
    def index(self):
        return self._count("index")

    def flush(self):
        return self._count("flush")()

    def state_dict(self):
        return self.inner.state_dict()

    def load_state_dict(self, state):
        return self.inner.load_state_dict(state)


def test_the_collector_asks_the_agent_once_per_step():
    """Per step the collector calls the agent once (``observe``, or ``observe_ends`` where
    episodes ended): the actions and the active rows are what the agent returned and what the
    collector retired, never asked for again; the batches are those of the agent driven
    directly (whose decisions the collector reads from its declared step state)."""
    env, agent = make(population=3, max_episode_steps=25)
    plain = list(HierarchicalCollector(env, agent, episodes=3, state=False))
    env, agent = make(population=3, max_episode_steps=25)
    counting = CountingAgent(agent)
    collector = HierarchicalCollector(env, counting, episodes=3, state=False)
    batches = list(collector)
    steps = sum(td.batch_size[0] for td in batches)
    assert steps == 75 and collector.finished and collector.num_active == 0
    assert counting.calls["observe"] + counting.calls["observe_ends"] == steps
    assert counting.calls["observe_ends"] == 3 and counting.calls["compact"] == 1
    assert counting.calls["actions"] == 0 and counting.calls["index"] <= 2  # built, started
    assert len(batches) == len(plain)
    for td, want in zip(batches, plain):
        for key in ("agent", "observation", "action", ("next", "reward"), ("next", "done")):
            assert torch.equal(td[key], want[key])
        assert "decision" in want.keys() and "decision" not in td.keys()
