"""The annealed exploration (--epsilon-init, --annealing-steps) and the MLP top level's learner
settings (--top-lr, --top-target-update, --top-bootstrap): what the trainer and the agent read,
resume, saved configs from before them, and the command line's refusals."""

import doctest

import numpy as np
import pytest
import torch

from skillchain_torch.agents.pieces import top_level_arguments
from skillchain_torch.policies import LinearEpsilon
from skillchain_torch.policies import epsilon_schedule as schedule_module
from skillchain_torch.presets import TOP_LEARNER
from skillchain_torch.trainers import (
    PopulationTrainer,
    TrainConfig,
    latest_checkpoint,
    load_checkpoint,
)
from skillchain_torch.trainers.config.cli import main

ANNEALED = TrainConfig(agent="skill-chaining", map="pinball_empty", runs=2, episodes=4, seed=3,
                       max_episode_steps=60, checkpoint_every=2, epsilon=0.0, epsilon_init=1.0,
                       annealing_steps=100)  # fmt: skip


def test_doctests():
    assert doctest.testmod(schedule_module).failed == 0


def test_linear_epsilon_is_linear_then_flat():
    schedule = LinearEpsilon(0.8, 0.1, 7)
    values = [schedule(t) for t in range(10)]
    assert values[0] == 0.8 and values[7:] == [0.1] * 3
    assert np.allclose(np.diff(values[:8]), -0.1)


@pytest.mark.parametrize("args", [(1.5, 0.1, 5), (0.5, -0.1, 5), (0.5, 0.1, 0)])
def test_linear_epsilon_refuses_impossible_values(args):
    with pytest.raises(ValueError, match="must be"):
        LinearEpsilon(*args)


def test_the_trainer_anneals_the_agents_epsilon_by_its_steps():
    trainer = PopulationTrainer(ANNEALED)
    assert trainer.agent.epsilon == 1.0  # the first decision explores at epsilon_init
    trainer.train(max_agent_steps=2 * 50)
    assert trainer.global_step == 50
    assert trainer.agent.epsilon == pytest.approx(0.5)
    trainer.train()
    assert trainer.agent.epsilon == 0.0  # past annealing_steps: epsilon


def test_annealing_changes_the_run_and_a_constant_epsilon_is_the_paper_s():
    constant = TrainConfig(**{**ANNEALED.to_dict(), "epsilon_init": None, "annealing_steps": 0})
    a = PopulationTrainer(ANNEALED).train()
    b = PopulationTrainer(constant).train()
    assert b.agent.epsilon == 0.0
    assert not np.array_equal(a.returns, b.returns)  # exploring at first changes the actions


def test_an_annealed_run_resumes_bit_for_bit(tmp_path):
    reference = PopulationTrainer(ANNEALED).train()
    interrupted = PopulationTrainer(ANNEALED, out_dir=tmp_path)

    def stop(trainer, path):
        raise KeyboardInterrupt

    interrupted.register_op("post_checkpoint", stop)
    with pytest.raises(KeyboardInterrupt):
        interrupted.train()
    resumed = PopulationTrainer(ANNEALED, out_dir=tmp_path)
    load_checkpoint(latest_checkpoint(tmp_path), resumed)
    assert resumed.agent.epsilon == LinearEpsilon(1.0, 0.0, 100)(resumed.global_step)
    resumed.train()
    assert np.array_equal(resumed.returns, reference.returns)
    assert np.array_equal(resumed.lengths, reference.lengths)


@pytest.mark.parametrize("fields", [dict(annealing_steps=5), dict(epsilon_init=1.0)])
def test_the_config_refuses_half_a_schedule(fields):
    with pytest.raises(ValueError, match="go together"):
        TrainConfig(agent="skill-chaining", **fields).validate()


def test_a_saved_config_from_before_the_fields_keeps_the_old_learner():
    old = {k: v for k, v in TrainConfig(agent="skill-chaining").to_dict().items()
           if k not in ("top_lr", "top_target_update", "top_bootstrap", "epsilon_init",
                        "annealing_steps")}  # fmt: skip
    cfg = TrainConfig.from_dict(old)
    assert (cfg.top_lr, cfg.top_target_update, cfg.top_bootstrap) == (1e-3, 250, "sarsa")
    assert cfg.epsilon_init is None and cfg.annealing_steps == 0
    new = TrainConfig(agent="skill-chaining")
    assert (new.top_lr, new.top_target_update, new.top_bootstrap) == tuple(TOP_LEARNER.values())


def test_the_mlp_top_level_takes_its_learner_settings():
    top = top_level_arguments("mlp", 2, 4, 7, seed=0,
                              learner=dict(lr=3e-4, target_update=7, bootstrap="sarsa"))
    learner = top["top_learner"]
    assert learner.optimizer.param_groups[0]["lr"] == 3e-4
    assert learner.updater.value_network_update_interval == 7
    assert learner.loss.bootstrap == "sarsa"
    default = top_level_arguments("mlp", 2, 4, 7, seed=0)["top_learner"]
    assert default.optimizer.param_groups[0]["lr"] == TOP_LEARNER["lr"]
    assert default.loss.bootstrap == TOP_LEARNER["bootstrap"]


def test_the_linear_top_level_refuses_a_learner():
    with pytest.raises(ValueError, match="closed-form Sarsa"):
        top_level_arguments("fourier", 2, 4, 7, learner=dict(lr=1e-3))


def test_the_trainer_s_agent_reads_the_config_s_learner():
    cfg = TrainConfig(agent="skill-chaining", runs=2, top_head="mlp", preset="paper",
                      top_lr=2e-4, top_target_update=9, top_bootstrap="sarsa")  # fmt: skip
    learner = PopulationTrainer(cfg).agent.top_learner
    assert learner.optimizer.param_groups[0]["lr"] == 2e-4
    assert learner.updater.value_network_update_interval == 9
    assert learner.loss.bootstrap == "sarsa"


@pytest.mark.parametrize("flags, message", [
    (["--top-lr", "0.1"], "--top-head mlp"),
    (["--top-bootstrap", "sarsa"], "--top-head mlp"),
    (["--epsilon-init", "1"], "go together"),
    (["--annealing-steps", "5"], "go together"),
    (["--epsilon-init", "2", "--annealing-steps", "5"], "epsilon_init must be in [0, 1]"),
    (["--top-head", "mlp", "--preset", "paper", "--top-target-update", "0"],
     "top_target_update must be >= 1"),
])  # fmt: skip
def test_the_command_line_refuses_in_one_line(flags, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "--agent", "skill-chaining", *flags, "--out", str(tmp_path / "run")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1]
    assert not (tmp_path / "run").exists()


def test_flat_reads_the_schedule_from_the_command_line(tmp_path):
    # (It was refused as a field flat never read; flat anneals through set_epsilon now.)
    out = tmp_path / "run"
    code = main(["train", "--agent", "flat", "--map", "pinball_empty", "--epsilon-init", "1",
                 "--annealing-steps", "5", "--runs", "2", "--episodes", "2",
                 "--max-episode-steps", "40", "--quiet", "--out", str(out)])  # fmt: skip
    assert code == 0
    saved = TrainConfig.load_json(out / "config.json")
    assert (saved.epsilon_init, saved.annealing_steps) == (1.0, 5)
    other = TrainConfig(**{**saved.to_dict(), "epsilon_init": 0.5})
    assert "epsilon_init" in saved.mismatches(other)  # a resume with another schedule refuses


def test_an_annealed_neural_run_learns_through_the_command_line(tmp_path):
    out = tmp_path / "run"
    code = main(["train", "--agent", "skill-chaining", "--preset", "paper", "--map",
                 "pinball_empty", "--top-head", "mlp", "--epsilon-init", "1",
                 "--annealing-steps", "50", "--epsilon", "0.05", "--runs", "2", "--episodes",
                 "2", "--max-episode-steps", "80", "--quiet", "--out", str(out)])  # fmt: skip
    assert code == 0
    saved = TrainConfig.load_json(out / "config.json")
    assert (saved.epsilon_init, saved.annealing_steps, saved.top_bootstrap) == (1.0, 50, "max")
    assert torch.isfinite(torch.from_numpy(np.load(out / "returns.npy"))).all()


def test_the_flat_agent_anneals_too():
    # Before set_epsilon the trainer assigned agent.epsilon, an attribute the flat agent never
    # reads: --epsilon-init was silently a constant epsilon for --agent flat.
    flat = TrainConfig(**{**ANNEALED.to_dict(), "agent": "flat"})
    trainer = PopulationTrainer(flat)
    assert trainer.agent.policy.epsilon == 1.0
    trainer.train(max_agent_steps=2 * 50)
    assert trainer.agent.policy.epsilon == pytest.approx(0.5)
    constant = PopulationTrainer(TrainConfig(**{**flat.to_dict(), "epsilon_init": None,
                                                "annealing_steps": 0})).train()  # fmt: skip
    assert not np.array_equal(PopulationTrainer(flat).train().returns, constant.returns)


def test_set_epsilon_refuses_a_value_outside_0_1():
    agent = PopulationTrainer(ANNEALED).agent
    with pytest.raises(ValueError, match=r"epsilon must be in \[0, 1\], got 1.5"):
        agent.set_epsilon(1.5)


def test_a_user_agent_without_set_epsilon_is_refused_in_one_line():
    plain = PopulationTrainer(TrainConfig(**{**ANNEALED.to_dict(), "epsilon_init": None,
                                             "annealing_steps": 0})).agent  # fmt: skip

    class NoSchedule:  # every EpisodeAgent method, delegated, but no set_epsilon
        population = plain.population

        def __getattr__(self, name):
            if name == "set_epsilon":
                raise AttributeError(name)
            return getattr(plain, name)

    with pytest.raises(ValueError, match="has no set_epsilon"):
        PopulationTrainer(ANNEALED, agent=NoSchedule())
