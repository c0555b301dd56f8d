"""Skill chaining through the trainer and the CLI: reproducibility, resume, outputs."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.backends import hierarchical as native_hierarchical
from skillchain_torch.options import OptionBank, OptionStatus
from skillchain_torch.trainers import PopulationTrainer, TrainConfig
from skillchain_torch.trainers.config.cli import main
from skillchain_torch.trainers.outputs.checkpoint import load_checkpoint
from skillchain_torch.trainers.outputs.discovery_log import DiscoveryLog, option_tree

# pinball_box: an open box where random play finds the hole within a few hundred steps, so
# agents create options in their first episodes, at different episodes.
KERNELS = [False, True] if native_hierarchical.AVAILABLE else [False]
BOX = dict(agent="skill-chaining", map="pinball_box", max_episode_steps=300, slots=4)


def trainer_for(runs, seed, episodes=8, gestation=2, native=None, starts=None, **kwargs):
    """A trainer whose agents gestate 2 episodes, so options join and learn in a short run
    (``native``: the agent's compiled kernels, default when built; ``starts``: the agent's
    ``policy_start`` / ``value_start`` / ``value_bonus``)."""
    config = TrainConfig(runs=runs, seed=seed, episodes=episodes, **{**BOX, **kwargs})
    trainer = PopulationTrainer(config, **({"out_dir": kwargs.pop("out_dir")}
                                           if "out_dir" in kwargs else {}))  # fmt: skip
    bank = OptionBank.build(runs, config.slots, seed=seed)
    trainer.agent = SkillChainingAgent(bank, order=4, alpha=0.001, seed=seed,
                                       gestation=gestation, native=native,
                                       **(starts or {}))  # fmt: skip
    return trainer


@pytest.mark.slow
@pytest.mark.parametrize("native", KERNELS)
def test_agent_alone_equals_agent_in_population(native):
    population = trainer_for(3, seed=5, native=native).train()
    assert population.agent.native is native
    created = population.agent.bank.created_episode
    assert len({tuple(row.tolist()) for row in created}) > 1  # spawned at different episodes
    assert (population.agent.bank.status >= OptionStatus.LEARNING).any()
    for p in range(3):
        alone = trainer_for(1, seed=5 + p, native=native).train()
        assert np.array_equal(alone.returns[0], population.returns[p])
        for name in ("status", "parent", "target_event", "created_episode"):
            assert torch.equal(getattr(alone.agent.bank, name)[0],
                               getattr(population.agent.bank, name)[p]), name
        assert torch.equal(alone.agent.bank.q_head.weight[0],
                           population.agent.bank.q_head.weight[p])
        assert torch.equal(alone.agent.bank.classifier.weight[0],
                           population.agent.bank.classifier.weight[p])
        assert torch.equal(alone.agent.q_head.weight[0], population.agent.q_head.weight[p])


@pytest.mark.slow
def test_agent_and_top_level_starts_keep_agents_independent():
    starts = dict(policy_start="top-level", value_start="agent", value_bonus=50.0)
    population = trainer_for(3, seed=5, starts=starts).train()
    joined = population.agent.bank.status >= OptionStatus.LEARNING
    assert joined.any()
    p, k = joined.nonzero()[0].tolist()
    assert population.agent.bank.q_head.weight[p, k].abs().max() > 0
    for p in range(3):
        alone = trainer_for(1, seed=5 + p, starts=starts).train()
        assert np.array_equal(alone.returns[0], population.returns[p])
        assert torch.equal(alone.agent.bank.q_head.weight[0],
                           population.agent.bank.q_head.weight[p])
        assert torch.equal(alone.agent.q_head.weight[0], population.agent.q_head.weight[p])


def test_resume_is_bit_identical(tmp_path):
    straight = trainer_for(2, seed=1, episodes=6).train()
    first = trainer_for(2, seed=1, episodes=6)
    first.out_dir = tmp_path
    first.train(max_agent_steps=1500)
    path = first.save_checkpoint(tmp_path / "mid.pt")
    resumed = trainer_for(2, seed=1, episodes=6)
    load_checkpoint(path, resumed)
    resumed.train()
    assert np.array_equal(resumed.returns, straight.returns)
    assert torch.equal(resumed.agent.bank.status, straight.agent.bank.status)
    assert torch.equal(resumed.agent.bank.q_head.weight, straight.agent.bank.q_head.weight)
    assert torch.equal(resumed.agent.bank.classifier.examples,
                       straight.agent.bank.classifier.examples)
    assert torch.equal(resumed.agent.q_head.weight, straight.agent.q_head.weight)


def test_discovery_log_counts_options_per_episode():
    trainer = trainer_for(2, seed=0, episodes=5)
    log = DiscoveryLog()
    log.register(trainer)
    trainer.train()
    live = trainer.agent.bank.live().sum(-1).numpy()
    assert (log.n_options >= 0).all() and np.array_equal(log.n_options[:, -1], live)
    assert (np.diff(log.n_options, axis=1) >= 0).all()  # slots are never freed
    assert log.totals["created"] == live.sum()
    tree = option_tree(trainer.agent)
    assert [len(a["options"]) for a in tree["agents"]] == live.tolist()
    for agent in tree["agents"]:
        for option in agent["options"]:
            assert (option["target"] == "goal") == (option["parent"] == -1)
            assert option["depth"] >= 1


def test_cli_writes_discovery_outputs_loadable_as_given_options(tmp_path, capsys):
    out = tmp_path / "sc"
    argv = ["train", "--agent", "skill-chaining", "--map", "pinball_box", "--runs", "2",
            "--episodes", "3", "--max-episode-steps", "300", "--slots", "3", "--quiet",
            "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    for name in ("returns.npy", "options.pt", "n_options.npy", "option_tree.json",
                 "learning_curve.png", "option_trajectory.png"):  # fmt: skip
        assert (out / name).is_file(), name
    # Where the time went, for issue 29's budget (monitoring and figures <= 10%).
    seconds = json.loads((out / "run_info.json").read_text())["seconds"]
    watched = ("option_monitor", "tensorboard", "discovery_log", "outputs")
    assert all(seconds[k] > 0 for k in ("train", *watched))
    assert seconds["monitoring_and_outputs"] == pytest.approx(sum(seconds[k] for k in watched))
    n_options = np.load(out / "n_options.npy")
    assert n_options.shape == (2, 3) and n_options.dtype == np.int64
    bank = OptionBank.load(out / "options.pt")
    assert bank.population == 2 and bank.slots == 3
    assert np.array_equal(bank.live().sum(-1).numpy(), n_options[:, -1])
    tree = json.loads((out / "option_tree.json").read_text())
    assert tree["slots"] == 3 and len(tree["agents"]) == 2
    given = tmp_path / "given"
    assert main(["train", "--agent", "given-options", "--options", str(out / "options.pt"),
                 "--options-agent", "each", "--map", "pinball_box", "--runs", "3",
                 "--episodes", "1", "--max-episode-steps", "50", "--quiet",
                 "--out", str(given)]) == 0  # fmt: skip
    assert json.loads((given / "config.json").read_text())["options_agent"] is None


def test_cli_errors(tmp_path, capsys):
    for argv, message in ((["--slots", "0"], "slots must be >= 1, got 0"),
                          (["--options-agent", "x"], "expected an agent index or 'each'"),
                          (["--initiation-bias", "nan"], "initiation_bias must be finite")):
        with pytest.raises(SystemExit):
            main(["train", "--agent", "skill-chaining", "--out", str(tmp_path / "x"), *argv])
        assert message in capsys.readouterr().err


def test_discovery_log_registered_after_loading_gets_its_state(tmp_path):
    first = trainer_for(2, seed=2, episodes=4)
    log = DiscoveryLog()
    log.register(first)
    first.out_dir = tmp_path
    first.train(max_agent_steps=1200)
    path = first.save_checkpoint(tmp_path / "mid.pt")
    resumed = trainer_for(2, seed=2, episodes=4)
    load_checkpoint(path, resumed)  # before the hook exists, as the CLI does
    again = DiscoveryLog()
    again.register(resumed)
    assert np.array_equal(again.n_options, log.n_options)
    assert again.totals == log.totals


def test_given_options_drop_gestating_slots_and_keep_out_of_parents(tmp_path):
    from skillchain_torch.agents.given_options import GivenOptionsAgent

    bank = OptionBank.build(1, 3, seed=0)
    one = torch.tensor([True])
    for kwargs, status in (({"target_event": 0}, OptionStatus.LEARNED),
                           ({"parent": 0}, OptionStatus.GESTATING),
                           ({"parent": 0}, OptionStatus.LEARNING)):  # fmt: skip
        slot = bank.allocate(one, **kwargs)
        bank.set_status(torch.nn.functional.one_hot(slot, 3).bool(), status)
    with torch.no_grad():  # slot 0: x > 0.6; slot 2 untrained (everywhere)
        bank.classifier.weight[0, 0, 1] = 1.0
        bank.classifier.bias[0, 0] = -0.6
        bank.classifier.trained[0, 0] = True
    bank.save(tmp_path / "options.pt")
    agent = GivenOptionsAgent(TrainConfig(agent="given-options", runs=2,
                                          options=str(tmp_path / "options.pt")))  # fmt: skip
    assert agent.bank.status[0].tolist() == [OptionStatus.LEARNED, OptionStatus.EMPTY,
                                             OptionStatus.LEARNED]  # fmt: skip
    inside = torch.tensor([[0.9, 0.5, 0.5, 0.5]] * 2, dtype=torch.float64)
    assert agent.membership(inside)[0].tolist() == [True, True, False]  # the child keeps out


def test_initiation_reading_reaches_the_classifiers():
    from skillchain_torch.agents.skill_chaining_run import SkillChainingRunAgent

    config = TrainConfig(runs=2, initiation_bias=2.5, initiation_centered=True, **BOX)
    classifier = SkillChainingRunAgent(config).bank.classifier
    assert classifier.config["initial_bias"] == 2.5 and classifier.config["centered"] is True
    assert classifier.bias.eq(2.5).all()
    default = SkillChainingRunAgent(TrainConfig(runs=1, **BOX)).bank.classifier
    assert default.config["initial_bias"] == 0.0 and default.config["centered"] is False


def test_gestation_and_convergence_reach_the_discovery_rules():
    from skillchain_torch.agents.skill_chaining_run import SkillChainingRunAgent

    default = SkillChainingRunAgent(TrainConfig(runs=1, **BOX)).discovery
    assert (default.gestation, default.convergence.threshold) == (2, 0.15)
    config = TrainConfig(runs=1, gestation=3, convergence_threshold=0.5, **BOX)
    discovery = SkillChainingRunAgent(config).discovery
    assert (discovery.gestation, discovery.convergence.threshold) == (3, 0.5)
    # a flat run never reads them, so it stays valid whatever they are
    flat = TrainConfig(runs=1).resolved()
    assert flat.mismatches(TrainConfig(runs=1, gestation=3).resolved()) == []


def test_shorter_gestation_joins_options_sooner():
    """Two agents alike but for gestation: each option joins ``gestation`` episodes after it is
    created, so with 1 episode the first option is executable long before it is with 10."""
    joined = {}
    for g in (1, 10):
        trainer = PopulationTrainer(TrainConfig(runs=2, episodes=6, seed=3, gestation=g, **BOX))
        trainer.train()
        joined[g] = [e for e in trainer.agent.discovery.log if e.kind == "joined"]
        created = {(e.agent, e.slot): e.episode for e in trainer.agent.discovery.log
                   if e.kind == "created"}  # fmt: skip
        assert all(e.episode - created[(e.agent, e.slot)] == g for e in joined[g])
    assert joined[1] and not joined[10]


@pytest.mark.parametrize("flag, value, message", [
    ("--gestation", "-1", "gestation must be in [0, 10^6]"),
    ("--convergence-threshold", "0", "convergence_threshold must be finite and > 0"),
])  # fmt: skip
def test_cli_refuses_bad_gestation_and_convergence(tmp_path, capsys, flag, value, message):
    with pytest.raises(SystemExit) as exit_:
        main(["train", "--agent", "skill-chaining", "--runs", "1", "--episodes", "1",
              flag, value, "--out", str(tmp_path / "run")])  # fmt: skip
    assert exit_.value.code == 2 and message in capsys.readouterr().err
