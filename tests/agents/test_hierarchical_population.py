"""HierarchicalAgent across agents and over time: a population equals its single runs, its
state survives a round trip and a checkpoint, and saved options drive the trainer."""

from __future__ import annotations

import dataclasses

import pytest
import torch
from hand_built import F64, REGION, make_agent, make_bank, obs, prefer_option

from skillchain_torch.agents import HierarchicalAgent, make_region_option
from skillchain_torch.collectors import HierarchicalCollector
from skillchain_torch.envs.pinball import PinballEnv
from skillchain_torch.options import (
    OptionBank,
    OptionStatus,
)


def run_collector(population, seed, steps, bank_seed_offset=0):
    bank = make_bank(population=population, slots=2, signs=(1.0, -1.0), order=2,
                     seed=seed + bank_seed_offset)
    agent = HierarchicalAgent(bank, order=2, alpha=0.001, epsilon=0.2, seed=seed,
                              events=(REGION,))
    env = PinballEnv("pinball_simple_single", batch_size=[population], seed=seed,
                     max_episode_steps=40)
    collector = HierarchicalCollector(env, agent, frames_per_batch=steps * population)
    return agent, collector.rollout()


def test_population_equals_single_runs():
    S, P, steps = 11, 3, 120
    pop, batch = run_collector(P, S, steps)
    assert bool((batch["option"] >= 0).any())  # options were executed
    assert bool(batch["next", "done"].any())  # and episodes restarted
    for p in (0, 2):
        alone, single = run_collector(1, S + p, steps)
        assert torch.equal(batch["decision"][:, p], single["decision"][:, 0])
        assert torch.equal(batch["action"][:, p], single["action"][:, 0])
        assert torch.equal(pop.q_head.weight[p], alone.q_head.weight[0])
        assert torch.equal(pop.bank.q_head.weight[p], alone.bank.q_head.weight[0])
        assert torch.equal(pop.rng.counter[p], alone.rng.counter[0])


def test_state_dict_round_trip():
    agent = make_agent(make_bank())
    prefer_option(agent)
    agent.begin(obs((0.7, 0.5, 0.5, 0.5)))
    agent.observe(obs((0.72, 0.5, 0.5, 0.5)), torch.tensor([-1.0], dtype=F64))
    state = agent.state_dict()
    other = make_agent(make_bank())
    other.load_state_dict(state)
    for a, b in ((agent, other),):
        assert torch.equal(a.q_head.weight, b.q_head.weight)
        assert torch.equal(a.bank.q_head.weight, b.bank.q_head.weight)
        assert torch.equal(a.rng.counter, b.rng.counter)
    s = obs((0.74, 0.5, 0.5, 0.5))
    r = torch.tensor([-1.0], dtype=F64)
    assert torch.equal(agent.observe(s, r), other.observe(s, r))
    assert torch.equal(agent.q_head.weight, other.q_head.weight)


def test_compact_keeps_rows():
    agent = make_agent(make_bank(population=3))
    agent.begin(obs(*[(0.3, 0.5, 0.5, 0.5)] * 3))
    agent.compact(torch.tensor([True, False, True]))
    assert agent.index.tolist() == [0, 2]
    assert agent.observe(obs(*[(0.31, 0.5, 0.5, 0.5)] * 2),
                         torch.full((2,), -1.0, dtype=F64)).shape == (2,)


def test_region_option_file_round_trip(tmp_path):
    bank = make_region_option(examples=200, pretrain_steps=30, batch=20)
    path = tmp_path / "region.pt"
    bank.save(path)
    loaded = OptionBank.from_agent(path, 0, 2, seeds=torch.tensor([5, 6]))
    assert loaded.status.tolist() == [[int(OptionStatus.LEARNED)]] * 2
    near = obs((0.85, 0.25, 0.5, 0.5), (0.2, 0.9, 0.5, 0.5))
    assert loaded.available(near)[:, 0].tolist() == [True, False]
    agent = HierarchicalAgent(loaded, seed=5)
    agent.q_head.weight[:, 5, 0] = 1e4
    agent.begin(near)
    assert agent.options.tolist() == [0, -1]


def test_given_options_agent(tmp_path):
    from skillchain_torch.agents.given_options import GivenOptionsAgent
    from skillchain_torch.trainers.config.config import TrainConfig

    path = tmp_path / "region.pt"
    make_region_option(examples=200, pretrain_steps=20, batch=20).save(path)

    @dataclasses.dataclass(frozen=True)
    class Config(TrainConfig):
        options: str | None = None

    agent = GivenOptionsAgent(Config(agent="flat", runs=2, seed=3, options=str(path)))
    assert agent.q_head.weight.shape == (2, 6, 625)
    assert agent.bank.status.tolist() == [[3], [3]]
    assert agent.rng.seeds.tolist() == [3, 4]
    with pytest.raises(ValueError, match="options"):
        GivenOptionsAgent(TrainConfig(runs=1))


def test_population_trainer_drives_given_options(tmp_path, monkeypatch):
    from skillchain_torch.trainers.config import registry
    from skillchain_torch.trainers.config.config import TrainConfig
    from skillchain_torch.trainers.loop.population import PopulationTrainer

    monkeypatch.setitem(registry.AGENTS, "given-options",
                        "skillchain_torch.agents.given_options:GivenOptionsAgent")
    bank = OptionBank.build(1, slots=2, order=2)  # untrained classifiers: available everywhere
    bank.status[0, 0] = int(OptionStatus.LEARNED)
    bank.target_event[0, 0] = 0  # the goal
    path = tmp_path / "everywhere.pt"
    bank.save(path)

    @dataclasses.dataclass(frozen=True)
    class Config(TrainConfig):
        options: str | None = None

    def train(runs, seed):
        cfg = Config(agent="given-options", runs=runs, seed=seed, episodes=2, order=2,
                     epsilon=0.2, max_episode_steps=60, options=str(path))
        trainer = PopulationTrainer(cfg).train()
        return trainer

    pop, alone = train(3, 7), train(1, 8)
    assert pop.agent.bank.status[:, 1].tolist() == [0, 0, 0]  # the empty slot stays empty
    assert pop.finished and pop.lengths.shape == (3, 2)
    assert (pop.returns[1] == alone.returns[0]).all()
    assert torch.equal(pop.weights[1], alone.weights[0])
    assert torch.equal(pop.agent.bank.q_head.weight[1], alone.agent.bank.q_head.weight[0])
    assert bool((pop.agent.bank.q_head.weight[:, 0] != 0).any())  # the option learned
    assert bool((pop.weights[:, 5] != 0).all(-1).any())  # and was chosen by the top level


def test_trainer_resume_matches_uninterrupted(tmp_path, monkeypatch):
    import io

    from skillchain_torch.trainers.config import registry
    from skillchain_torch.trainers.config.config import TrainConfig
    from skillchain_torch.trainers.loop.population import PopulationTrainer

    monkeypatch.setitem(registry.AGENTS, "given-options",
                        "skillchain_torch.agents.given_options:GivenOptionsAgent")
    bank = OptionBank.build(1, slots=1, order=2)
    bank.status[0, 0] = int(OptionStatus.LEARNED)
    bank.target_event[0, 0] = 0
    path = tmp_path / "everywhere.pt"
    bank.save(path)

    @dataclasses.dataclass(frozen=True)
    class Config(TrainConfig):
        options: str | None = None

    cfg = Config(agent="given-options", runs=2, seed=1, episodes=3, order=2, epsilon=0.2,
                 max_episode_steps=40, options=str(path))
    full = PopulationTrainer(cfg).train()
    first = PopulationTrainer(cfg).train(max_agent_steps=130)  # stops mid-episode
    buffer = io.BytesIO()
    torch.save(first.state_dict(), buffer)
    buffer.seek(0)
    resumed = PopulationTrainer(cfg)
    resumed.load_state_dict(torch.load(buffer, weights_only=True))
    resumed.train()
    assert (resumed.returns == full.returns).all()
    assert torch.equal(resumed.weights, full.weights)
    assert torch.equal(resumed.agent.bank.q_head.weight, full.agent.bank.q_head.weight)
