"""Any environment with a bounded vector observation and discrete actions (issue 29): Gymnasium
ids through TorchRL's GymEnv, and an env registered by the user's own module."""

from __future__ import annotations

import json
import textwrap

import numpy as np
import pytest
import torch

from skillchain_torch.envs.external import make_env, parse_bounds, read_specs
from skillchain_torch.trainers import PopulationTrainer, TrainConfig
from skillchain_torch.trainers.config.cli import main
from skillchain_torch.trainers.study.verify import verify_run

MOUNTAIN_CAR = "gymnasium:MountainCar-v0"


@pytest.mark.parametrize("agent", ["flat", "skill-chaining"])
def test_agents_run_on_mountain_car_with_sizes_from_the_specs(agent):
    cfg = TrainConfig(agent=agent, env=MOUNTAIN_CAR, runs=2, episodes=2, seed=0,
                      max_episode_steps=60)  # fmt: skip
    trainer = PopulationTrainer(cfg)
    seen = []
    original = trainer.stepper.step

    def spy(action):
        seen.append(action.clone())
        return original(action)

    trainer.stepper.step = spy
    trainer.train()
    assert (trainer.config.obs_dim, trainer.config.num_actions) == (2, 3)
    assert trainer.config.order == 4  # the highest order up to 4 with <= 10,000 features
    assert trainer.config.alpha == 0.001 * 625 / 25  # Pinball's alpha x features, per feature
    assert (trainer.lengths == 60).all() and np.isfinite(trainer.returns).all()
    actions = torch.cat(seen)
    assert int(actions.min()) >= 0 and int(actions.max()) <= 2  # 3 actions, never Pinball's 4
    if agent == "skill-chaining":
        assert trainer.agent.bank.obs_dim == 2 and trainer.agent.num_decisions == 3 + 12


def test_option_step_size_follows_the_envs_option_basis():
    """The paper's alpha_o is stated for Pinball's 4-d order-3 option basis (256 features); off
    Pinball a preset's value is scaled to the env's basis, as alpha is, and a given one is kept
    (unscaled, the paper's 0.0005 diverged on LunarLander's 65,536 option features)."""
    from skillchain_torch.agents import SkillChainingAgent

    lander = dict(agent="skill-chaining", preset="paper", env="gymnasium:LunarLander-v3",
                  obs_dim=8, num_actions=4)  # fmt: skip
    assert TrainConfig(**lander).option_alpha is None  # left to resolved(), as alpha is
    assert TrainConfig(**lander).validate(memory=False).resolved().option_alpha == 0.0005 / 256
    car = dict(agent="skill-chaining", preset="paper", env=MOUNTAIN_CAR, obs_dim=2, num_actions=3)
    assert TrainConfig(**car).resolved().option_alpha == 0.0005 * 16  # 16 features, not 256
    assert TrainConfig(**car, option_alpha=0.01).resolved().option_alpha == 0.01  # given: kept
    assert TrainConfig(agent="skill-chaining", preset="paper").resolved().option_alpha == 0.0005
    assert TrainConfig(**{**car, "preset": "default"}).resolved().option_alpha == 0.0  # frozen
    saved = {**TrainConfig(**car).resolved().to_dict(), "option_alpha": 0.0005}
    assert TrainConfig.from_dict(saved).resolved().option_alpha == 0.0005  # a saved run: as run
    built = SkillChainingAgent.build(2, preset="paper", obs_dim=8, num_actions=4, order=1)
    assert built.bank.q_head.config["alpha"] == 0.0005 / 256  # the Python API agrees
    built = SkillChainingAgent.build(2, preset="paper", obs_dim=8, num_actions=4, order=1,
                                     option_alpha=0.1)  # fmt: skip
    assert built.bank.q_head.config["alpha"] == 0.1
    built = SkillChainingAgent.build(2, preset="paper", obs_dim=2, num_actions=3)
    via_config = TrainConfig(**car).resolved()  # the two entry points apply one rule
    assert (built.order, built.update.alpha) == (via_config.order, via_config.alpha) == (4, 0.025)
    assert built.bank.q_head.config["alpha"] == via_config.option_alpha


def test_given_options_run_on_mountain_car(tmp_path):
    sc = TrainConfig(agent="skill-chaining", env=MOUNTAIN_CAR, runs=1, episodes=1, seed=0,
                     max_episode_steps=20)  # fmt: skip
    trainer = PopulationTrainer(sc).train()
    trainer.agent.bank.save(tmp_path / "options.pt")
    given = TrainConfig(agent="given-options", env=MOUNTAIN_CAR, runs=2, episodes=1, seed=5,
                        max_episode_steps=20, options=str(tmp_path / "options.pt"))  # fmt: skip
    run = PopulationTrainer(given).train()
    assert run.agent.bank.obs_dim == 2 and (run.lengths == 20).all()


def test_given_options_from_another_env_are_refused(tmp_path):
    PopulationTrainer(TrainConfig(agent="skill-chaining", runs=1, episodes=1,
                                  max_episode_steps=5)).train().agent.bank.save(  # fmt: skip
        tmp_path / "pinball.pt")
    given = TrainConfig(agent="given-options", env=MOUNTAIN_CAR, runs=1, episodes=1,
                        options=str(tmp_path / "pinball.pt"))  # fmt: skip
    with pytest.raises(ValueError, match="obs_dim|map"):
        PopulationTrainer(given)


def test_a_run_on_a_gym_env_verifies_agent_by_agent(tmp_path):
    """The seed contract off Pinball: agent p of a population is the single run seed + p."""
    cfg = TrainConfig(agent="flat", env=MOUNTAIN_CAR, runs=3, episodes=2, seed=11,
                      max_episode_steps=40, epsilon=0.5)  # fmt: skip
    trainer = PopulationTrainer(cfg).train()
    trainer.write_results(tmp_path)
    trainer.config.save_json(tmp_path / "config.json")
    assert [r["match"] for r in verify_run(tmp_path, [0, 2])] == [True, True]


def test_unbounded_observations_ask_for_bounds():
    env = make_env("gymnasium:CartPole-v1")
    with pytest.raises(ValueError, match=r"no finite bounds.*--obs-bounds LOW:HIGH,LOW:HIGH"):
        read_specs(env)
    sizes = read_specs(env, "-2.4:2.4,-3:3,-0.21:0.21,-3.5:3.5")
    assert sizes.obs_dim == 4 and sizes.num_actions == 2
    scaled = sizes.scale(torch.tensor([[2.4, -3.0, 0.0, 0.0]], dtype=torch.float64))
    assert scaled.tolist() == [[1.0, 0.0, 0.5, 0.5]]


@pytest.mark.parametrize("text, message", [
    ("0:1", "gives 1 pairs"), ("0:1,1:0", "need finite LOW < HIGH"), ("0:1,a:b", "not LOW:HIGH"),
])  # fmt: skip
def test_bad_bounds_are_one_line_errors(text, message):
    with pytest.raises(ValueError, match=message):
        parse_bounds(text, 2)


def test_an_env_from_the_users_own_module(tmp_path, monkeypatch):
    """``gymnasium:MODULE:ID``: the module registers the id when imported."""
    (tmp_path / "my_chain.py").write_text(textwrap.dedent('''
        import gymnasium as gym
        import numpy as np

        class Chain(gym.Env):
            """Walk right along [0, 1]; the goal is x >= 1 (terminated)."""
            observation_space = gym.spaces.Box(0.0, 1.0, (1,), np.float64)
            action_space = gym.spaces.Discrete(2)

            def __init__(self, render_mode=None):
                self.render_mode = render_mode

            def reset(self, seed=None, options=None):
                super().reset(seed=seed)
                self.x = 0.0
                return np.array([self.x]), {}

            def step(self, action):
                self.x = min(1.0, max(0.0, self.x + (0.25 if action == 1 else -0.25)))
                done = self.x >= 1.0
                return np.array([self.x]), (10.0 if done else -1.0), done, False, {}

        gym.register(id="MyChain-v0", entry_point=Chain)
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    cfg = TrainConfig(agent="skill-chaining", env="gymnasium:my_chain:MyChain-v0", runs=2,
                      episodes=5, seed=0, max_episode_steps=50)  # fmt: skip
    trainer = PopulationTrainer(cfg).train()
    assert (trainer.config.obs_dim, trainer.config.num_actions) == (1, 2)
    assert (trainer.lengths < 50).any()  # the goal is reached: terminated ends the episode


def test_cli_env_flags(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "--env", MOUNTAIN_CAR, "--agent", "flat", "--runs", "1",
                 "--episodes", "1", "--max-episode-steps", "10", "--out", str(out)]) == 0
    config = json.loads((out / "config.json").read_text())
    assert (config["env"], config["obs_dim"], config["num_actions"]) == (MOUNTAIN_CAR, 2, 3)
    assert config["map"] is None  # a Pinball map it never read is not recorded
    for argv, message in (
        (["--env", MOUNTAIN_CAR, "--map", "pinball_simple_single"], "choose the environment"),
        (["--env", "NoSuchEnv-v0"], "cannot make"),  # a bare id is Gymnasium's (issue 54)
        (["--env", "gymnasium:NoSuchEnv-v0"], "cannot make"),
        (["--obs-bounds", "0:1"], "applies to --env only"),
    ):
        with pytest.raises(SystemExit) as exit_info:
            main(["train", *argv, "--out", str(tmp_path / "bad")])
        assert exit_info.value.code == 2
        assert message in capsys.readouterr().err


def test_a_run_with_replay_is_refused_by_verify_in_one_line(tmp_path, capsys):
    """A network's batched matmuls may round differently for a population of one
    (results/neural/README.md): re-running one agent alone need not reproduce it bit for bit,
    so verify says so instead of reporting a mismatch."""
    cfg = TrainConfig(agent="skill-chaining", preset="paper", runs=2, episodes=1,
                      max_episode_steps=10, top_head="mlp")  # fmt: skip
    trainer = PopulationTrainer(cfg).train()
    trainer.write_results(tmp_path)
    trainer.config.save_json(tmp_path / "config.json")
    with pytest.raises(ValueError, match="--top-head mlp cannot be re-run agent by agent"):
        verify_run(tmp_path, [0])
    with pytest.raises(SystemExit) as info:
        main(["verify", str(tmp_path), "--agents", "0"])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "re-run the whole command" in err[-1] and "Traceback" not in "\n".join(err)


def test_an_env_config_names_no_map():
    """``env`` and ``map`` each choose the environment: a config takes one. Env runs saved
    before the rule recorded the default map they never read, and load without it."""
    assert TrainConfig().map == "pinball_simple_single"
    assert TrainConfig(env=MOUNTAIN_CAR).map is None
    with pytest.raises(ValueError, match="choose the environment twice"):
        TrainConfig(env=MOUNTAIN_CAR, map="pinball_box")
    older = {**TrainConfig(env=MOUNTAIN_CAR).to_dict(), "map": "pinball_simple_single"}
    assert TrainConfig.from_dict(older).map is None
