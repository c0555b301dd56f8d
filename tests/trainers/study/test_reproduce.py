"""``skillchain reproduce paper`` and ``skillchain verify`` on a tiny study (issue 15)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest


def skillchain(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "skillchain_torch.trainers.config.cli", *args],
                          capture_output=True, text=True, cwd=cwd, timeout=600)  # fmt: skip


@pytest.mark.slow
def test_reproduce_resumes_and_its_runs_verify(tmp_path):
    out = tmp_path / "paper"
    args = ("reproduce", "paper", "--out", str(out), "--runs", "2", "--episodes", "3",
            "--instances", "simple", "--quiet")  # fmt: skip
    first = skillchain(*args)
    assert first.returncode == 0, first.stderr
    for agent in ("flat", "skill-chaining", "given-options"):
        run = out / "simple" / agent
        assert np.load(run / "returns.npy").shape == (2, 3)
        assert json.loads((run / "config.json").read_text())["seed"] == 1000
        assert "commit" in json.loads((run / "run_info.json").read_text())
    for agent in ("flat", "skill-chaining", "given-options"):  # blocks as jobs, one per core
        assert sorted(p.name for p in (out / "simple" / agent / "blocks").iterdir()) == [
            "0-1", "1-2"]
    timing = json.loads((out / "timing.json").read_text())
    assert timing["invocations"][0]["complete"] and len(timing["invocations"][0]["runs"]) == 3
    assert (out / "README.md").read_text().count("| claim |") == 1
    assert (out / "fig4a.png").is_file()
    stamp = (out / "simple" / "flat" / "run_info.json").stat().st_mtime
    again = skillchain(*args)  # every run is done: nothing is trained again
    assert again.returncode == 0, again.stderr
    assert (out / "simple" / "flat" / "run_info.json").stat().st_mtime == stamp
    for agent in ("skill-chaining", "given-options"):
        check = skillchain("verify", str(out / "simple" / agent), "--agents", "1")
        assert check.returncode == 0 and "match (1 of 1" in check.stdout, check.stdout
    # banks are too big to publish: without one, the skill-chaining agent is re-run to rebuild it
    (out / "simple" / "skill-chaining" / "options.pt").unlink()
    rebuilt = skillchain("verify", str(out / "simple" / "given-options"), "--agents", "1")
    assert rebuilt.returncode == 0 and "match (1 of 1" in rebuilt.stdout, rebuilt.stdout
    assert (out / "simple" / "skill-chaining" / "verify-options" / "agent1.pt").is_file()
    returns = np.load(out / "simple" / "flat" / "returns.npy")
    returns[1, 2] += 1.0
    np.save(out / "simple" / "flat" / "returns.npy", returns)
    bad = skillchain("verify", str(out / "simple" / "flat"), "--agents", "1")
    assert bad.returncode == 1 and "MISMATCH" in bad.stdout
    outside = skillchain("verify", str(out / "simple" / "flat"), "--agents", "5")
    assert outside.returncode == 2 and "agent 5 is not in" in outside.stderr


def test_figures_take_the_trained_agents_of_a_sharded_run_from_a_block(tmp_path):
    """A run sharded on Ray keeps its checkpoints in its blocks: the figures take the block
    whose agents hold the most options and label its agents by their place in the run."""
    from skillchain_torch.trainers.config.config import TrainConfig
    from skillchain_torch.trainers.distributed.block_run import run_block
    from skillchain_torch.trainers.distributed.blocks import block_config
    from skillchain_torch.trainers.study.paper_figures import load_trained, trained_agents

    cfg = TrainConfig(agent="skill-chaining", map="pinball_box", runs=3, episodes=3, seed=11,
                      max_episode_steps=300, checkpoint_every=1, gestation=1).resolved()
    out = tmp_path / "run"
    out.mkdir()
    cfg.save_json(out / "config.json")
    spans = [(0, 1), (1, 3)]
    (out / "sharding.json").write_text(json.dumps({"workers": 2, "blocks": spans}))
    held = {}
    for a, b in spans:
        block = out / "blocks" / f"{a}-{b}"
        run_block(block_config(cfg, a, b, block), block)
        bank = load_trained(block).agent.bank
        held[a] = float(bank.live().sum(-1).double().mean())
    with pytest.raises(ValueError, match="no checkpoint"):
        load_trained(out)  # the merged run has none of its own
    trainer, first = trained_agents(out)
    assert first == max(held, key=lambda a: (held[a], -a))
    assert trainer.agent.population == dict(spans)[first] - first
    block, offset = trained_agents(out / "blocks" / "1-3")  # an ordinary run: its own agents
    assert offset == 0 and block.agent.population == 2


def test_jobs_of_a_run_resume_where_it_stopped(tmp_path):
    """A new run is cut into one block per job; finished blocks are skipped; once all are
    done only the merge is left; an older study's interrupted one-process run stays whole."""
    from skillchain_torch.trainers.study.reproduce import _jobs_of, paper_experiments

    exp = paper_experiments(runs=5, episodes=2, instances=("simple",))[0]
    jobs = _jobs_of(exp, tmp_path, jobs=2)
    assert [(j.kind, j.span) for j in jobs] == [("block", (0, 3)), ("block", (3, 5))]
    assert json.loads((tmp_path / exp.name / "sharding.json").read_text())["blocks"] == [
        [0, 3], [3, 5]]
    (tmp_path / exp.name / "blocks" / "0-3").mkdir(parents=True)
    (tmp_path / exp.name / "blocks" / "0-3" / "block.json").write_text("{}")
    assert [j.label for j in _jobs_of(exp, tmp_path, jobs=4)] == ["simple/flat[3-5]"]  # kept
    (tmp_path / exp.name / "blocks" / "3-5").mkdir(parents=True)
    (tmp_path / exp.name / "blocks" / "3-5" / "block.json").write_text("{}")
    assert [j.kind for j in _jobs_of(exp, tmp_path, jobs=2)] == ["merge"]
    old = tmp_path / "old"
    (old / exp.name / "checkpoints").mkdir(parents=True)
    exp.config.save_json(old / exp.name / "config.json")
    (old / exp.name / "checkpoints" / "ckpt_000001.pt").write_bytes(b"")
    assert [j.kind for j in _jobs_of(exp, old, jobs=2)] == ["run"]
