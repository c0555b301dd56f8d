"""A sharded skill-chaining run on a Gymnasium env merges into a one-process run's files. Its
merge used to fail: Figure 4b resumed each block from its checkpoint, which an env whose
simulator state is not saved refuses; the agents are now read from the checkpoints alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from skillchain_torch.trainers import TrainConfig
from skillchain_torch.trainers.distributed.block_merge import merge_blocks, run_wall_time
from skillchain_torch.trainers.distributed.block_run import run_block
from skillchain_torch.trainers.distributed.blocks import ShardedRun, block_config


def test_sharded_env_skill_chaining_run_merges(tmp_path: Path):
    config = TrainConfig(agent="skill-chaining", env="gymnasium:MountainCar-v0", runs=3,
                         episodes=2, max_episode_steps=40, slots=2, checkpoint_every=1)
    run = ShardedRun(config, tmp_path, [(0, 2), (2, 3)])
    records = {span: run_block(block_config(config, *span, run.block_dir(span)),
                               run.block_dir(span)) for span in run.spans}  # fmt: skip
    info = merge_blocks(run, records, workers=2, wall=1.0)
    assert info["blocks"] == 2
    assert np.load(tmp_path / "returns.npy").shape == (3, 2)
    for name in ("option_trajectory.png", "options.pt", "option_tree.json", "learning_curve.png"):
        assert (tmp_path / name).is_file(), name


def test_a_killed_driver_does_not_understate_the_run_wall_time(tmp_path: Path):
    """A driver killed at a session's end records no time; the resumed driver's merge then
    reported only its own share (1,716 s for 10,513 s of work). The blocks' times survive."""
    config = TrainConfig(map="pinball_box", runs=2, episodes=1, max_episode_steps=20)
    run = ShardedRun(config, tmp_path, [(0, 1), (1, 2)])
    records = {span: run_block(block_config(config, *span, run.block_dir(span)),
                               run.block_dir(span)) for span in run.spans}  # fmt: skip
    records[(0, 1)] = {**records[(0, 1)], "wall_time_s": 500.0}  # work done by a killed driver
    info = merge_blocks(run, records, workers=2, wall=3.0)
    assert info["wall_time_s"] == 500.0
    assert info["agent_steps_per_second"] == info["agent_steps"] / 500.0
    assert run_wall_time(3.0, records) == 500.0 and run_wall_time(900.0, records) == 900.0
