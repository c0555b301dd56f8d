"""``skillchain train --preset`` and ``TrainConfig.preset``: the CLI, the config and
``SkillChainingAgent.build`` read one set of presets and build the same agents."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.agents.skill_chaining_run import SkillChainingRunAgent
from skillchain_torch.presets import DEFAULT, PAPER, PRESET_FIELDS
from skillchain_torch.trainers import PopulationTrainer, TrainConfig
from skillchain_torch.trainers.config.cli import _config_from_args, build_parser, main
from skillchain_torch.trainers.config.config import PRESET_CONFIG_FIELDS, UNREAD_FIELDS
from skillchain_torch.trainers.config.fields import LEGACY_FIELDS

ROOT = Path(__file__).resolve().parents[2]
BOX = ["--map", "pinball_box", "--max-episode-steps", "300", "--quiet"]


def config_of(*argv: str) -> TrainConfig:
    parser = build_parser()
    return _config_from_args(parser, parser.parse_args(["train", "--out", "unused", *argv]))


def same_agents(a: SkillChainingAgent, b: SkillChainingAgent) -> None:
    """Equal state (every tensor bit for bit) and equal settings."""
    sa, sb = a.state_dict(), b.state_dict()
    flat_a, flat_b = _flatten(sa), _flatten(sb)
    assert flat_a.keys() == flat_b.keys()
    for key, value in flat_a.items():
        other = flat_b[key]
        if isinstance(value, torch.Tensor):
            assert value.dtype == other.dtype and torch.equal(value, other), key
        else:
            assert value == other, key
    assert a.extra_repr() == b.extra_repr()
    assert a.bank.classifier.config == b.bank.classifier.config
    assert a.bank.q_head.config == b.bank.q_head.config


def _flatten(state, prefix=""):
    if isinstance(state, dict):
        out = {}
        for k, v in state.items():
            out.update(_flatten(v, f"{prefix}{k}."))
        return out
    return {prefix: state}


def test_config_fields_a_preset_fills_are_preset_fields():
    assert set(PRESET_CONFIG_FIELDS) <= set(PRESET_FIELDS)
    preset = {k: getattr(DEFAULT, k) for k in PRESET_CONFIG_FIELDS}
    assert TrainConfig().to_dict() == {**TrainConfig().to_dict(), **preset, "slots": 12}
    hard = TrainConfig(map="pinball_hard_two_starts")
    assert (preset["slots"], hard.slots, TrainConfig(env="CartPole-v1").slots) == (None, 48, 12)
    assert TrainConfig(map="pinball_hard_two_starts", slots=12).slots == 12  # given wins


@pytest.mark.parametrize("preset", ["default", "paper"])
def test_the_cli_and_build_configure_the_same_agent(preset):
    cfg = config_of("--agent", "skill-chaining", "--preset", preset, "--runs", "2",
                    "--seed", "11")
    assert cfg.preset == preset
    from_cli = SkillChainingRunAgent(cfg)
    from_build = SkillChainingAgent.build(population=2, preset=preset, seed=11)
    same_agents(from_cli, from_build)


def test_an_explicit_flag_overrides_the_preset():
    cfg = config_of("--agent", "skill-chaining", "--preset", "paper", "--gestation", "3",
                    "--option-alpha", "0.25")
    assert (cfg.gestation, cfg.option_alpha) == (3, 0.25)
    assert (cfg.policy_start, cfg.value_start, cfg.gestation_positives) == (
        "zero", "max-sample", 0)  # the rest is the paper's
    agent = SkillChainingRunAgent(cfg)
    assert (agent.discovery.gestation, agent.bank.q_head.config["alpha"]) == (3, 0.25)


def test_an_unknown_preset_is_one_line_naming_the_valid_ones(capsys, tmp_path):
    with pytest.raises(SystemExit) as info:
        main(["train", "--preset", "papers", "--out", str(tmp_path / "run")])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--preset" in err and "'default'" in err and "'paper'" in err, err
    path = tmp_path / "config.json"
    path.write_text(json.dumps({**TrainConfig().to_dict(), "preset": "papers"}))
    with pytest.raises(ValueError, match=r"unknown preset 'papers'; valid presets: default, paper"):
        TrainConfig.load_json(path)


def test_preset_paper_lands_the_papers_values_in_config_json(tmp_path):
    out = tmp_path / "run"
    assert main(["train", "--agent", "skill-chaining", "--preset", "paper", "--runs", "1",
                 "--episodes", "1", "--slots", "2", "--out", str(out), *BOX]) == 0
    saved = json.loads((out / "config.json").read_text())
    assert saved["preset"] == "paper"
    expected = {k: getattr(PAPER, k) for k in PRESET_CONFIG_FIELDS if k != "slots"}
    expected.update(order=4, alpha=0.001)  # the paper's, for the first instance
    assert {k: saved[k] for k in expected} == expected
    assert saved["gestation"] == 10 and saved["policy_start"] == "zero"
    assert TrainConfig.load_json(out / "config.json").preset == "paper"


def test_build_default_and_the_cli_default_agent_give_the_same_returns(tmp_path):
    """The agent ``skillchain train`` builds by default is ``build(preset="default")``: the
    same returns on a short run in which options are created and join."""
    out = tmp_path / "cli"
    assert main(["train", "--agent", "skill-chaining", "--runs", "2", "--seed", "3",
                 "--episodes", "5", "--out", str(out), *BOX]) == 0
    config = TrainConfig.load_json(out / "config.json")
    assert config.preset == "default"
    trainer = PopulationTrainer(config)
    trainer.agent = SkillChainingAgent.build(population=2, preset="default", seed=3)
    trainer.train()
    assert np.array_equal(trainer.returns, np.load(out / "returns.npy"))
    assert np.array_equal(trainer.lengths, np.load(out / "lengths.npy"))
    assert int(trainer.agent.bank.live().sum()) > 0  # discovery took part


def test_committed_configs_without_a_preset_load_as_the_default():
    """Every run published before presets ran the default preset's values, but for fields
    added after them, which load with the value every run before them had (``LEGACY_FIELDS``:
    ``end_outside_set`` "off", the default now "learned"). The configs are those of the study
    ``results/paper-v3`` (in git at 6835785), kept in ``tests/data/legacy_configs``."""
    paths = sorted((ROOT / "tests" / "data" / "legacy_configs").glob("*.json"))
    assert len(paths) == 6
    for path in paths:
        raw = json.loads(path.read_text())
        assert "preset" not in raw
        config = TrainConfig.load_json(path)
        assert config.preset == "default"
        assert not config.mismatches(config)
        unread = set(UNREAD_FIELDS[config.agent])
        later = {k for k in LEGACY_FIELDS if k not in raw}
        default = TrainConfig(map=config.map)
        differ = {k for k in PRESET_CONFIG_FIELDS if k not in unread | {"order", "alpha"}
                  and getattr(config, k) != getattr(default, k)}
        if "slots" in differ:  # 12 everywhere until the hard instance's became 48
            assert "hard" in config.map and config.slots == 12
            differ.remove("slots")
        assert differ <= later, (path, differ - later)
        assert all(getattr(config, k) == LEGACY_FIELDS[k] for k in differ)
        if config.agent != "flat":
            assert config.end_outside_set == "off" != DEFAULT.end_outside_set


def test_the_published_study_ran_todays_default():
    """``results/paper/`` is the study of the library's default: every run's values are the
    default preset's (a changed default must re-run the study or move it aside)."""
    paths = sorted((ROOT / "results" / "paper").glob("*/*/config.json"))
    assert len(paths) == 6
    for path in paths:
        config = TrainConfig.load_json(path)
        unread = set(UNREAD_FIELDS[config.agent]) | {"order", "alpha"}
        default = TrainConfig(map=config.map)  # (slots: the map's, 48 on the hard instance)
        differ = [k for k in PRESET_CONFIG_FIELDS
                  if k not in unread and getattr(config, k) != getattr(default, k)]
        assert differ == [], (path, differ)


def test_the_preset_label_alone_is_no_mismatch():
    """``preset`` names where the values came from; the values decide whether runs differ."""
    paper = TrainConfig(agent="skill-chaining", preset="paper")
    relabelled = TrainConfig(**{**paper.to_dict(), "preset": "default"})
    assert relabelled.gestation == 10 and not paper.mismatches(relabelled)
    assert "gestation" in paper.mismatches(TrainConfig(agent="skill-chaining"))


def test_a_fourier_top_level_does_not_read_the_mlp_learner():
    """The paper preset's MLP learner values are unread by a Fourier top level: a run saved
    before they existed is the same run, while two MLP runs that differ in them differ."""
    paper = TrainConfig(agent="skill-chaining", preset="paper")
    older = TrainConfig(**{**paper.to_dict(), "top_lr": 1e-3, "top_target_update": 250,
                           "top_bootstrap": "sarsa"})  # fmt: skip
    assert paper.top_head == "fourier" and paper.mismatches(older) == []
    mlp = dataclasses.replace(paper, top_head="mlp")
    assert mlp.mismatches(dataclasses.replace(older, top_head="mlp")) == [
        "top_lr", "top_target_update", "top_bootstrap"]


def test_the_study_takes_a_preset():
    """``skillchain reproduce paper --preset paper --slots 48``: every run of the study under
    the paper's values, given options reading the study's own discoverers."""
    from skillchain_torch.trainers.study.reproduce import paper_experiments

    exps = {e.name: e for e in paper_experiments(preset="paper", slots=48)}
    assert len(exps) == 6 and exps["hard/flat"].config.runs == 100
    sc, given = exps["simple/skill-chaining"].config, exps["simple/given-options"].config
    assert (sc.preset, sc.gestation, sc.slots, sc.end_outside_set) == ("paper", 10, 48, "off")
    assert given.options == "simple/skill-chaining/options.pt" and given.gestation == 10
    default = {e.name: e.config for e in paper_experiments()}
    assert default["simple/skill-chaining"].mismatches(sc)  # the two studies differ
    assert not default["simple/flat"].mismatches(exps["simple/flat"].config)  # but not flat


def test_subgoals_random_reaches_the_agent_and_a_bad_value_is_one_line(capsys):
    """Issue 52's control (b) from the command line: ``--subgoals random`` builds the goal and
    one random disc per other slot, with chaining off; an unknown value is refused."""
    from skillchain_torch.agents.skill_chaining_run import SkillChainingRunAgent

    config = config_of("--agent", "skill-chaining", "--subgoals", "random", "--slots", "3",
                       "--runs", "2")  # fmt: skip
    assert config.subgoals == "random"
    agent = SkillChainingRunAgent(config)
    assert [e.name for e in agent.events] == ["goal", "subgoal 1", "subgoal 2"]
    assert not agent.discovery.chaining
    assert config_of("--agent", "skill-chaining").resolved().subgoals == "chained"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["train", "--subgoals", "nearby"])
    assert "invalid choice: 'nearby'" in capsys.readouterr().err


def test_neural_heads_take_the_default_and_the_shifted_start_names_the_flag(capsys, tmp_path):
    """Issue 53: the default's two starts are fitted in a neural head's last layer, so MLP
    heads train under the default; only the shifted start, which reads the linear values,
    refuses them, in one line naming the flag that fixes it."""
    cfg = config_of("--agent", "skill-chaining", "--top-head", "mlp", "--option-head", "mlp")
    assert (cfg.policy_start, cfg.value_start) == ("top-level", "agent")
    cfg.validate(memory=False)  # (tests/neural/test_neural_starts.py trains under it)
    agent = SkillChainingAgent.build(1, option_head="mlp", top_head="mlp", order=1)
    assert (agent.discovery.policy_start, agent.discovery.value_start) == ("top-level", "agent")
    with pytest.raises(SystemExit):
        main(["train", "--agent", "skill-chaining", "--option-head", "mlp", "--policy-start",
              "top-level-shifted", "--runs", "1", "--episodes", "1",
              "--out", str(tmp_path / "shifted")])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "use --policy-start top-level" in err


def test_the_option_time_limit_is_a_flag_that_reaches_both_option_agents(tmp_path, capsys):
    """Section 5.1's 250-step limit, changeable (issue 53's run on the cause of the neural gap):
    --max-option-steps reaches the skill-chaining and given-options agents, 0 is refused in one
    line, and a saved config from before the field ran with 250."""
    assert config_of("--agent", "skill-chaining").max_option_steps == DEFAULT.max_option_steps
    cfg = TrainConfig(agent="skill-chaining", map="pinball_box", runs=1, episodes=1,
                      max_episode_steps=30, max_option_steps=50)
    trainer = PopulationTrainer(cfg, out_dir=tmp_path / "sc")
    trainer.train()
    assert trainer.agent.max_option_steps == 50
    assert trainer.agent.discovery.max_option_steps == 50
    trainer.agent.bank.save(tmp_path / "options.pt")
    given = TrainConfig(agent="given-options", map="pinball_box", runs=1, episodes=1,
                        max_episode_steps=30, max_option_steps=7,
                        options=str(tmp_path / "options.pt"))
    assert PopulationTrainer(given).agent.max_option_steps == 7
    with pytest.raises(SystemExit):
        main(["train", "--agent", "skill-chaining", "--max-option-steps", "0", "--out",
              str(tmp_path / "bad")])
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "max_option_steps must be in [1, 10^6], got 0" in err
    assert LEGACY_FIELDS["max_option_steps"] == 250 == PAPER.max_option_steps
