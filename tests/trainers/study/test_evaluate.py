"""``skillchain eval`` and ``load_run`` (issue 54): a run's agents loaded from its checkpoint,
evaluated frozen (no learning, no discovery, the evaluation's own streams), one agent drawn as
a GIF; a folder without a checkpoint is one line."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from skillchain_torch.trainers import PopulationTrainer, TrainConfig
from skillchain_torch.trainers.config.cli import main
from skillchain_torch.trainers.study.evaluate import evaluate, load_run


@pytest.fixture(scope="module")
def sc_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("sc")
    config = TrainConfig(agent="skill-chaining", map="pinball_box", runs=3, episodes=4,
                         max_episode_steps=400, seed=5)  # fmt: skip
    config.save_json(out / "config.json")
    trainer = PopulationTrainer(config, out_dir=out).train()
    return out, trainer


def test_load_run_gives_the_trained_agents(sc_run):
    out, trainer = sc_run
    run = load_run(out)
    assert run.config == trainer.config and run.checkpoint.name == "ckpt_000004.pt"
    assert torch.equal(run.agent.q_head.weight, trainer.agent.q_head.weight)
    assert torch.equal(run.agent.bank.status, trainer.agent.bank.status)


def test_evaluation_is_frozen_and_reproducible(sc_run):
    out, _ = sc_run
    run = load_run(out)
    before = run.agent.q_head.weight.clone(), run.agent.bank.q_head.weight.clone()
    a = evaluate(run, episodes=2, max_steps=300)
    b = evaluate(run, episodes=2, max_steps=300)
    assert a.returns.shape == (3, 2) and np.array_equal(a.returns, b.returns)
    assert (a.lengths <= 300).all()
    assert torch.equal(run.agent.q_head.weight, before[0])  # the run's agents untouched
    assert torch.equal(run.agent.bank.q_head.weight, before[1])
    other = evaluate(run, episodes=2, max_steps=300, epsilon=0.5, seed=1)
    assert not np.array_equal(other.lengths, a.lengths)  # exploration and streams matter
    assert "mean over 3 agents" in a.table() and "95% t interval" in a.table()


def test_a_flat_run_evaluates_without_learning(tmp_path):
    config = TrainConfig(agent="flat", map="pinball_box", runs=2, episodes=2,
                         max_episode_steps=300)  # fmt: skip
    config.save_json(tmp_path / "config.json")
    PopulationTrainer(config, out_dir=tmp_path).train()
    run = load_run(tmp_path)
    weights = run.agent.q_head.weight.clone()
    result = evaluate(run, episodes=3, max_steps=200)
    assert result.returns.shape == (2, 3) and torch.equal(run.agent.q_head.weight, weights)


def test_cli_eval_prints_the_table_and_draws_a_gif(sc_run, capsys, tmp_path):
    out, _ = sc_run
    gif = tmp_path / "agent1.gif"
    assert main(["eval", str(out), "--episodes", "2", "--max-steps", "200", "--quiet",
                 "--render", str(gif), "--agent-index", "1"]) == 0
    text = capsys.readouterr().out
    assert "skill-chaining agents from ckpt_000004.pt" in text and "| 2 |" in text
    from PIL import Image

    assert Image.open(gif).size == (400, 400)


@pytest.mark.parametrize("argv, message", [
    (["--agent-index", "7"], "--agent-index must be in [0, 2], got 7"),
    (["--epsilon", "2"], "--epsilon must be in [0, 1], got 2.0"),
])
def test_cli_eval_bad_values_are_one_line(sc_run, capsys, argv, message):
    out, _ = sc_run
    with pytest.raises(SystemExit):
        main(["eval", str(out), "--quiet", *argv])
    err = capsys.readouterr().err.strip()
    assert message in err and err.count("\n") == 0


def test_a_run_without_a_checkpoint_is_one_line(tmp_path, capsys):
    TrainConfig(runs=1).save_json(tmp_path / "config.json")
    with pytest.raises(SystemExit):
        main(["eval", str(tmp_path)])
    err = capsys.readouterr().err.strip()
    assert "no checkpoint under" in err and "arrays and figures only" in err
    assert err.count("\n") == 0


def test_eval_shows_a_progress_bar(sc_run, capsys):
    out, _ = sc_run
    assert main(["eval", str(out), "--episodes", "1", "--max-steps", "100"]) == 0
    assert "3/3" in capsys.readouterr().err  # one episode of each of the 3 agents
