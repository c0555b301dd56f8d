"""Figure 4b's replays: batched episodes equal the one-at-a-time ones, and the early stop of
best_greedy_trajectory picks the same episode."""

import math

import numpy as np
import pytest

from skillchain_torch.trainers import PopulationTrainer, TrainConfig
from skillchain_torch.trainers.outputs.option_trajectory import (
    _replay,
    best_greedy_trajectory,
    greedy_trajectories,
    greedy_trajectory,
    solution_rank,
)

MAP, STEPS = "pinball_box", 300


@pytest.fixture(scope="module")
def trained():
    # 3 agents x 8 episodes on the small map: each holds options, and their replays mix
    # goals through options, goals by primitives alone and episodes cut at STEPS.
    config = TrainConfig(agent="skill-chaining", map=MAP, runs=3, episodes=8, seed=0)
    trainer = PopulationTrainer(config).train()
    runs = [(p, s, 0.0 if s == 0 else trainer.agent.epsilon) for p in range(3) for s in range(3)]
    single = [greedy_trajectory(trainer.agent, p, MAP, STEPS, seed=s, epsilon=e)
              for p, s, e in runs]
    return trainer.agent, runs, single


def same(a: dict, b: dict) -> bool:
    return (a.keys() == b.keys() and np.array_equal(a["states"], b["states"])
            and np.array_equal(a["options"], b["options"])
            and all(a[k] == b[k] for k in ("return", "terminated", "agent", "epsilon")))


def test_batched_equals_one_at_a_time(trained):
    agent, runs, single = trained
    kinds = {(r["terminated"], bool((r["options"] >= 0).any())) for r in single}
    assert (True, True) in kinds and len(kinds) >= 2  # the case mixes outcomes
    batched = greedy_trajectories(agent, MAP, runs, STEPS)
    assert all(same(a, b) for a, b in zip(single, batched))


def test_best_stops_early_but_picks_the_same(trained):
    agent, runs, single = trained
    best = best_greedy_trajectory(agent, MAP, agents=[0, 1, 2], max_steps=STEPS, tries=3)
    assert same(best, max(single, key=solution_rank))
    # A bound no episode can beat stops every one of them (None).
    greedy = [i for i, run in enumerate(runs) if run[2] == 0.0]
    rows, seeds = [runs[i][0] for i in greedy], [runs[i][1] for i in greedy]
    assert _replay(agent, MAP, rows, seeds, 0.0, STEPS, best=[1e9]) == [None] * len(rows)
    # From no bound: the episodes that finish raise it; those stopped rank below the best.
    kept = _replay(agent, MAP, rows, seeds, 0.0, STEPS, best=[-math.inf])
    top = max((single[i] for i in greedy), key=solution_rank)
    for i, run in zip(greedy, kept):
        assert same(run, single[i]) if run is not None else (
            solution_rank(single[i]) < solution_rank(top))
