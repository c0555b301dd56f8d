"""``skillchain train --workers N``: blocks of agents on Ray, merged bit for bit (issue 16)."""

import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from skillchain_torch.trainers import PopulationTrainer, TrainConfig
from skillchain_torch.trainers.config.cli import main
from skillchain_torch.trainers.distributed.blocks import ShardedRun, block_spans
from skillchain_torch.trainers.distributed.ray_runs import run_sharded

TINY = dict(runs=4, episodes=3, max_episode_steps=200, seed=3)


def _flags(**fields) -> list[str]:
    return [arg for k, v in fields.items() for arg in (f"--{k.replace('_', '-')}", str(v))]


def _one_process(**fields) -> PopulationTrainer:
    return PopulationTrainer(TrainConfig(**fields)).train()


def _same(out, reference) -> None:
    np.testing.assert_array_equal(np.load(out / "returns.npy"), reference.returns)
    np.testing.assert_array_equal(np.load(out / "lengths.npy"), reference.lengths)


@pytest.mark.parametrize("agent", ["flat", pytest.param("skill-chaining", marks=pytest.mark.slow)])
def test_sharded_run_equals_one_process(ray_local, tmp_path, agent):
    """4 agents in blocks of 1 over 2 workers: the one-process arrays, bit for bit, and the
    one-process outputs around them."""
    fields = dict(agent=agent, **TINY) | ({"slots": 2} if agent == "skill-chaining" else {})
    out = tmp_path / "run"
    assert main(["train", *_flags(**fields), "--out", str(out), "--workers", "2",
                 "--block-size", "1", "--quiet"]) == 0
    reference = _one_process(**fields)
    _same(out, reference)
    info = json.loads((out / "run_info.json").read_text())
    assert (info["workers"], info["blocks"], info["block_size"]) == (2, 4, 1)
    assert info["agent_steps"] == reference.agent_steps
    assert TrainConfig.load_json(out / "config.json") == reference.config
    assert (out / "learning_curve.png").is_file() and any((out / "tb").rglob("events.*"))
    if agent == "skill-chaining":
        from skillchain_torch.options import OptionBank

        merged = OptionBank.load(out / "options.pt").state_dict()
        for key, value in reference.agent.bank.state_dict().items():
            assert np.array_equal(merged[key].numpy(), value.numpy()), key
        tree = json.loads((out / "option_tree.json").read_text())
        assert [a["agent"] for a in tree["agents"]] == [0, 1, 2, 3]
        assert np.load(out / "n_options.npy").shape == (4, 3)
        # Figure 4b: the same episode drawn, its candidates replayed from the blocks
        one = tmp_path / "one"
        import torch

        threads = torch.get_num_threads()
        torch.set_num_threads(1)  # the one-process replay runs at torch's setting: on a busy
        try:  # machine 2 threads take 10x longer (benchmarks/README.md, ray_sharding.py)
            assert main(["train", *_flags(**fields), "--out", str(one), "--quiet"]) == 0
        finally:
            torch.set_num_threads(threads)
        assert ((out / "option_trajectory.png").read_bytes()
                == (one / "option_trajectory.png").read_bytes())


def test_sharded_given_options_each(ray_local, tmp_path):
    """--options-agent each: agent p takes saved agent p mod N's options, in any block."""
    import torch

    from skillchain_torch.options import OptionBank

    saved = OptionBank.load(Path(__file__).parents[2] / "benchmarks/data/skill_chaining_options.pt")
    banks = [saved]
    for kept in (4, 2):  # saved agents 1 and 2 hold fewer of the 9 options
        bank = saved.select_agents([0])
        bank.free(torch.arange(bank.slots)[None] >= kept)
        banks.append(bank)
    OptionBank.concat(banks).save(tmp_path / "options.pt")
    fields = dict(agent="given-options", options=str(tmp_path / "options.pt"), runs=4,
                  episodes=2, max_episode_steps=200, seed=5)
    out = tmp_path / "go"
    assert main(["train", *_flags(**fields), "--options-agent", "each", "--out", str(out),
                 "--workers", "2", "--block-size", "1", "--quiet"]) == 0
    _same(out, _one_process(**fields, options_agent=None))


def test_killed_worker_is_recovered(ray_local, tmp_path):
    """A worker that dies after its block's first checkpoint: Ray re-runs the task, which
    resumes that checkpoint; the merged run is still the one-process run, steps counted once."""
    config = TrainConfig(agent="flat", checkpoint_every=1, **TINY).resolved()
    marker = tmp_path / "crashed"
    run = ShardedRun(config, tmp_path / "run", block_spans(4, 2))
    run.out.mkdir()
    [info] = run_sharded([run], workers=2, quiet=True, crash_once=str(marker))
    assert marker.exists()  # a worker did die
    reference = _one_process(**dataclasses.asdict(config))
    _same(run.out, reference)
    assert info["agent_steps"] == reference.agent_steps


def test_resume_after_an_interrupted_driver(ray_local, tmp_path):
    """--resume RUN_DIR: finished blocks are kept, an unfinished one resumes from its newest
    checkpoint; the result and the step count are those of an uninterrupted run."""
    fields = dict(agent="flat", checkpoint_every=1, **TINY)
    out = tmp_path / "run"
    argv = ["train", *_flags(**fields), "--out", str(out), "--workers", "2", "--block-size",
            "2", "--quiet"]
    assert main(argv) == 0
    steps = json.loads((out / "run_info.json").read_text())["agent_steps"]
    # As a driver killed mid-run leaves it: no merged outputs, block 2-4 after its first
    # checkpoint only, block 0-2 finished.
    (out / "returns.npy").unlink()
    block = out / "blocks" / "2-4"
    for name in ("block.json", "returns.npy", "lengths.npy"):
        (block / name).unlink()
    for path in sorted((block / "checkpoints").glob("ckpt_*.pt"))[1:]:
        path.unlink()
    done = (out / "blocks" / "0-2" / "block.json").stat().st_mtime_ns
    assert main(["train", "--resume", str(out), "--quiet"]) == 0
    _same(out, _one_process(**fields))
    assert (out / "blocks" / "0-2" / "block.json").stat().st_mtime_ns == done  # not re-run
    assert json.loads((out / "run_info.json").read_text())["agent_steps"] == steps


def test_overwrite_does_not_reuse_blocks(ray_local, tmp_path):
    """--overwrite of a sharded run removes its blocks: the new run's rows are its own."""
    out = tmp_path / "run"
    base = ["train", *_flags(**TINY), "--out", str(out), "--workers", "2", "--quiet"]
    assert main(base) == 0
    assert main([*base[:-1], "--seed", "11", "--overwrite", "--quiet"]) == 0
    _same(out, _one_process(**{**TINY, "seed": 11}))


@pytest.mark.slow
def test_interrupted_driver_then_resume(ray_local, tmp_path):
    """A real interruption: the driver (a process of its own, on the session's Ray) gets
    SIGINT after a block's first checkpoint and exits 130; --resume finishes the run with the
    one-process arrays and step count."""
    import signal
    import subprocess
    import time

    fields = dict(agent="flat", runs=4, episodes=40, seed=2, checkpoint_every=5)
    out = tmp_path / "run"
    address = ray_local.get_runtime_context().gcs_address
    driver = subprocess.Popen(
        [sys.executable, "-m", "skillchain_torch.trainers.config.cli", "train", *_flags(**fields),
         "--out", str(out), "--workers", "2", "--block-size", "1", "--quiet", "--ray-address",
         address], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while not list(out.glob("blocks/*/checkpoints/ckpt_*.pt")):
        assert driver.poll() is None and time.monotonic() < deadline, driver.stderr.read()
        time.sleep(0.2)
    driver.send_signal(signal.SIGINT)
    assert driver.wait(timeout=120) == 130
    assert "continue with: skillchain train --resume" in driver.stderr.read()
    assert not (out / "returns.npy").exists()
    assert main(["train", "--resume", str(out), "--quiet"]) == 0
    reference = _one_process(**fields)
    _same(out, reference)
    assert json.loads((out / "run_info.json").read_text())["agent_steps"] == reference.agent_steps


@pytest.mark.parametrize("argv", [["--workers", "2"], ["--workers", "2", "--block-size", "1"]])
def test_missing_ray_is_one_line(tmp_path, capsys, monkeypatch, argv):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray raises ImportError
    with pytest.raises(SystemExit) as info:
        main(["train", "--runs", "2", "--out", str(tmp_path / "run"), *argv])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.endswith("--workers needs Ray, which is not installed: pip install "
                        "skillchain_torch[ray]"), err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(("argv", "message"), [
    (["--workers", "0"], "--workers: expected a positive integer, got 0"),
    (["--block-size", "2"], "--block-size needs --workers N with N > 1"),
    (["--workers", "2", "--block-size", "0"], "--block-size: expected a positive integer, got 0"),
    (["--workers", "2", "--block-size", "5"], "--block-size must be at most --runs (4), got 5"),
    (["--workers", "2", "--block-size", "few"], "expected a number of agents or 'shrink'"),
])
def test_sharding_flags_are_checked(tmp_path, capsys, argv, message):
    with pytest.raises(SystemExit) as info:
        main(["train", "--runs", "4", "--out", str(tmp_path / "run"), *argv])
    assert info.value.code == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("runs", [1, 2, 7, 30, 100])
@pytest.mark.parametrize("workers", [1, 2, 3, 16])
def test_shrinking_blocks_cover_every_agent_once(runs, workers):
    from skillchain_torch.trainers.distributed.blocks import guided_spans

    spans = guided_spans(runs, workers)
    assert [a for a, _ in spans] == [0] + [b for _, b in spans[:-1]] and spans[-1][1] == runs
    sizes = [b - a for a, b in spans]
    assert sizes == sorted(sizes, reverse=True) and sizes[-1] == 1


@pytest.mark.parametrize("name", ["distributed.blocks", "distributed.block_run",
                                  "distributed.block_merge", "distributed.ray_runs"])
def test_doctests(name):
    import doctest
    import importlib

    module = importlib.import_module(f"skillchain_torch.trainers.{name}")
    assert doctest.testmod(module, optionflags=doctest.ELLIPSIS).failed == 0


def test_default_blocks_are_one_per_worker_and_shrink_is_guided():
    """Measured on an idle machine, batching beats balancing (benchmarks/README.md): by default
    each worker takes one block; ``shrink`` is the guided schedule."""
    from skillchain_torch.trainers.distributed.blocks import guided_spans, plan_blocks

    assert plan_blocks(100, 2) == [(0, 50), (50, 100)]
    assert plan_blocks(7, 3) == [(0, 3), (3, 6), (6, 7)]
    assert plan_blocks(10, 2, "shrink") == guided_spans(10, 2)
    assert plan_blocks(10, 2, 4) == [(0, 4), (4, 8), (8, 10)]


def test_resume_with_more_episodes_extends_a_sharded_run(ray_local, tmp_path):
    """--resume RUN_DIR --episodes N on a sharded run: every block continues from its newest
    checkpoint before an agent finished (the later ones and block.json set aside), and the
    merged run is the one-process run of N episodes, bit for bit; interrupted once extended,
    it resumes from the extension's own checkpoints."""
    fields = dict(agent="flat", checkpoint_every=1, **TINY)
    out = tmp_path / "run"
    assert main(["train", *_flags(**fields), "--out", str(out), "--workers", "2",
                 "--block-size", "2", "--quiet"]) == 0
    assert main(["train", "--resume", str(out), "--episodes", "5", "--quiet"]) == 0
    longer = dict(fields, episodes=5)
    _same(out, _one_process(**longer))
    assert TrainConfig.load_json(out / "config.json").episodes == 5
    block = out / "blocks" / "0-2"
    assert TrainConfig.load_json(block / "config.json").episodes == 5
    assert (block / "checkpoints" / "superseded" / "block.json").is_file()
    # Interrupted after the extension: the block resumes from the extension's checkpoints.
    for name in ("block.json", "returns.npy", "lengths.npy"):
        (block / name).unlink()
    for path in sorted((block / "checkpoints").glob("ckpt_*.pt"))[-2:]:
        path.unlink()
    assert main(["train", "--resume", str(out), "--quiet"]) == 0
    _same(out, _one_process(**longer))


def test_a_sharded_run_that_cannot_be_extended_is_left_as_it_was(ray_local, tmp_path, capsys):
    """One block without a checkpoint from before an agent finished: one line naming it, and
    no block moved or rewritten (every block is checked before any file changes)."""
    fields = dict(agent="flat", checkpoint_every=1, **TINY)
    out = tmp_path / "run"
    assert main(["train", *_flags(**fields), "--out", str(out), "--workers", "2",
                 "--block-size", "2", "--quiet"]) == 0
    for path in sorted((out / "blocks" / "2-4" / "checkpoints").glob("ckpt_*.pt"))[:-1]:
        path.unlink()  # only the checkpoint after its agents finished is left
    before = {p: p.read_bytes() for p in sorted((out / "blocks").rglob("*")) if p.is_file()}
    with pytest.raises(SystemExit):
        main(["train", "--resume", str(out), "--episodes", "5", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "blocks/2-4" in err and "cannot be extended" in err
    after = {p: p.read_bytes() for p in sorted((out / "blocks").rglob("*")) if p.is_file()}
    assert after == before
    assert TrainConfig.load_json(out / "config.json").episodes == 3
