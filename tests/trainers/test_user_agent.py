"""An agent of the user's own composition handed to ``PopulationTrainer(agent=...)``: checked
against the env before the run, recorded as what it is, and written out as the CLI writes a run
(the README's "Your own pieces" snippet, run here at a small budget)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.options import OptionBank
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

ROOT = Path(__file__).resolve().parents[2]


def readme_snippet() -> str:
    text = (ROOT / "README.md").read_text()
    start = text.index("```python\n", text.index("Your own pieces\n")) + len("```python\n")
    return text[start:text.index("```\n", start)]


def test_an_agent_sized_for_pinball_is_refused_on_another_env_in_one_line():
    agent = SkillChainingAgent(OptionBank.build(2, 3, order=1), order=1)
    with pytest.raises(ValueError, match=r"built for 4 observation dims and 5 actions but "
                       r"gymnasium:MountainCar-v0 has 2 and 3"):  # fmt: skip
        PopulationTrainer(TrainConfig(runs=2, episodes=1, env="gymnasium:MountainCar-v0"),
                          agent=agent)  # fmt: skip
    with pytest.raises(ValueError, match="holds 2 agents but the config asks for runs=3"):
        PopulationTrainer(TrainConfig(runs=3, episodes=1), agent=agent)


def test_config_json_describes_the_users_agent_not_the_configs(tmp_path):
    """The config's agent fields build an agent by name; for the user's agent they were never
    used, so config.json leaves them null and names the class (it used to say "flat", order 4,
    gestation 2 for a skill-chaining agent of order 1 and gestation 10)."""
    agent = SkillChainingAgent(OptionBank.build(2, 3, order=1), order=1, gestation=10)
    trainer = PopulationTrainer(TrainConfig(runs=2, episodes=1, max_episode_steps=20,
                                            checkpoint_every=0), agent=agent)  # fmt: skip
    trainer.train().write_results(tmp_path)
    saved = json.loads((tmp_path / "config.json").read_text())
    assert saved["agent"] == "user:SkillChainingAgent"
    assert saved["order"] is None and saved["gestation"] is None and saved["preset"] is None
    assert (saved["runs"], saved["episodes"], saved["max_episode_steps"]) == (2, 1, 20)
    built = PopulationTrainer(TrainConfig(runs=2, episodes=1, max_episode_steps=20))
    assert built.user_agent is False  # a run built by name keeps its config as it is
    built.train().write_results(tmp_path / "named")
    assert json.loads((tmp_path / "named" / "config.json").read_text())["agent"] == "flat"


def test_readme_snippet_runs_and_writes_what_the_cli_writes(tmp_path):
    code = readme_snippet().replace("episodes=30", "episodes=2")
    code = code.replace('"runs/mine"', repr(str(tmp_path / "mine")))
    assert code != readme_snippet()
    exec(compile(code, "README.md", "exec"), {"__name__": "readme"})
    out = tmp_path / "mine"
    for name in ("returns.npy", "config.json", "learning_curve.png", "options.pt",
                 "option_tree.json", "run_info.json"):
        assert (out / name).exists(), name
    assert json.loads((out / "config.json").read_text())["agent"] == "user:SkillChainingAgent"
    runs = [p.name for p in (out / "tb").iterdir()]
    assert runs == ["SkillChainingAgent_pinball_simple_single_P4_seed0"], runs
    assert not [p for p in (out / "tb" / runs[0]).iterdir() if p.is_dir()]  # no hparams run
    events = b"".join(p.read_bytes() for p in (out / "tb" / runs[0]).iterdir())
    assert b"_hparams_/session_start_info" in events and b"gestation" in events  # hparams here
    with pytest.raises(ValueError, match="built in Python, not by name"):
        TrainConfig.load_json(out / "config.json")


def test_a_diverged_user_agent_gets_advice_for_python_and_its_own_record(tmp_path):
    """The divergence advice names no flag (no flag set the user's step sizes), and
    diverged.json records the user's agent, not the config's."""
    from skillchain_torch.trainers.loop.population import Diverged

    agent = SkillChainingAgent(OptionBank.build(2, 2, order=1), order=1)
    trainer = PopulationTrainer(TrainConfig(runs=2, episodes=3, max_episode_steps=30,
                                            checkpoint_every=0), out_dir=tmp_path, agent=agent)

    def poison(trainer, batch):
        trainer.agent.q_head.weight.view(-1)[0] = float("nan")

    trainer.register_op("post_episodes", poison)
    with pytest.raises(Diverged, match="lower its step size where you built the agent"):
        trainer.train()
    saved = json.loads((tmp_path / "diverged.json").read_text())
    assert saved["config"]["agent"] == "user:SkillChainingAgent"
    assert "--alpha" not in saved["error"]
