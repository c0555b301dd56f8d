"""Issue 52: do the paper's own mechanisms against a runaway act in the faithful reading's
runaway agents? Each measured at every timed-out execution.

The faithful reading (``paper-b2`` of ``screen100.sh``) ran away in 10 of 100 screening agents
(seeds 3, 6, 13, 28, 34, 47, 56, 57, 61, 80: an episode over 20,000 steps after episode 50).
This script re-runs such agents alone (agent p alone is agent p of the population, bit for bit)
and records, at every execution that times out (the 250-step limit fired):

* ``q_start``: ``Q(s0, o)`` of the option at its start state ``s0`` when it was chosen;
* ``q_after``: ``Q(s0, o)`` after the SMDP update of that failure (the paper: failures lower
  ``Q(s, o)``), and ``best_primitive``: ``max_a Q(s0, a)`` then (is the option still the
  better choice at its failed start?);
* ``in_before`` / ``in_after``: whether ``s0`` is in the option's initiation set before and
  after the refit that follows (the paper: failed starts leave the set).

    python results/faithful/mechanisms.py OUT.npz [--seeds 3 6 ...] [--episodes 250]

Prints, per agent and in all, the timeouts, the share of the agent's steps spent in timed-out
executions, how far a failure lowers ``Q(s0, o)``, how often the option stays the better choice
at ``s0``, and how often ``s0`` stays in the set. Screening seeds only.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from skillchain_torch.discovery import SkillChaining
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

RUNAWAY = (3, 6, 13, 28, 34, 47, 56, 57, 61, 80)  # paper-b2's, seeds 0-99 (screen100.sh)
FAITHFUL = dict(agent="skill-chaining", preset="paper", initiation_start="biased",
                initiation_bias=2.0, initiation_centered=True, map="pinball_simple_single")
COLUMNS = ("seed", "episode", "slot", "q_start", "q_after", "best_primitive", "in_before",
           "in_after")  # fmt: skip


def measure(seed: int, episodes: int, rows: list) -> np.ndarray:
    """Train the faithful reading's agent ``seed`` alone, appending a row per timeout."""
    trainer = PopulationTrainer(TrainConfig(runs=1, episodes=episodes, seed=seed, **FAITHFUL))
    agent = trainer.agent
    primitives = agent.num_primitives
    started: dict[int, float] = {}

    def q_at(obs: torch.Tensor, decisions: slice | int) -> torch.Tensor:
        phi = agent.features(obs[None].to(torch.float64))
        return agent.q_head(phi)[0, decisions]

    start = SkillChaining.start_executions
    finish = SkillChaining._finish_executions

    def start_executions(self, rows, slot):
        start(self, rows, slot)
        if bool(rows[0]):  # (one agent: row 0) the value it was chosen with, at s0 = agent.obs
            started[int(slot[0])] = float(q_at(agent.obs[0], primitives + int(slot[0])))

    def finish_executions(self, option, reached, duration, ended, terminated):
        k = int(option[0])
        timeout = bool(ended[0]) and k >= 0 and not bool(reached[0, k]) \
            and int(duration[0]) >= self.max_option_steps and not bool(terminated[0])
        if timeout:
            s0 = self.trace.states[0, 0].clone()
            clf = self.bank.classifier
            before = bool(clf.contains_points(0, k, s0[None])[0])
            q_after = float(q_at(s0, primitives + k))
            best = float(q_at(s0, slice(0, primitives)).max())
        finish(self, option, reached, duration, ended, terminated)
        if timeout:
            after = bool(clf.contains_points(0, k, s0[None])[0])
            rows.append((seed, int(self.episode[0]), k, started.get(k, np.nan), q_after, best,
                         before, after))  # fmt: skip

    SkillChaining.start_executions = start_executions
    SkillChaining._finish_executions = finish_executions
    try:
        trainer.train()
    finally:
        SkillChaining.start_executions = start
        SkillChaining._finish_executions = finish
    return np.asarray(trainer.lengths)[0]


def summary(rows: np.ndarray, lengths: dict[int, np.ndarray], limit: int = 250) -> str:
    lines = ["| seed | steps | timeouts | share of steps in timeouts | Q(s0, o) lowered by a "
             "failure (median) | option still above max_a Q(s0, a) after it | s0 still in the "
             "set after the refit | s0 in the set before it |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for seed in sorted(lengths):
        r = rows[rows[:, 0] == seed] if rows.size else rows
        steps = int(lengths[seed].sum())
        if r.size == 0:
            lines.append(f"| {seed} | {steps:,} | 0 | 0% | - | - | - | - |")
            continue
        drop = np.nanmedian(r[:, 3] - r[:, 4])
        lines.append(f"| {seed} | {steps:,} | {len(r):,} | {100 * len(r) * limit / steps:.0f}% | "
                     f"{drop:,.0f} | {100 * (r[:, 4] > r[:, 5]).mean():.0f}% | "
                     f"{100 * r[:, 7].mean():.0f}% | {100 * r[:, 6].mean():.0f}% |")
    if rows.size:
        steps = sum(int(v.sum()) for v in lengths.values())
        lines.append(f"| all | {steps:,} | {len(rows):,} | "
                     f"{100 * len(rows) * limit / steps:.0f}% | "
                     f"{np.nanmedian(rows[:, 3] - rows[:, 4]):,.0f} | "
                     f"{100 * (rows[:, 4] > rows[:, 5]).mean():.0f}% | "
                     f"{100 * rows[:, 7].mean():.0f}% | {100 * rows[:, 6].mean():.0f}% |")
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="where the rows go (.npz)")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(RUNAWAY))
    parser.add_argument("--episodes", type=int, default=250)
    args = parser.parse_args(argv)
    rows: list = []
    lengths = {}
    for seed in args.seeds:
        lengths[seed] = measure(seed, args.episodes, rows)
        print(f"seed {seed}: {int(lengths[seed].sum()):,} steps, "
              f"{sum(r[0] == seed for r in rows)} timeouts", flush=True)
        np.savez(args.out, rows=np.asarray(rows, dtype=np.float64), columns=COLUMNS,
                 **{f"lengths_{s}": v for s, v in lengths.items()})  # (after every agent)
    table = summary(np.asarray(rows, dtype=np.float64).reshape(-1, len(COLUMNS)), lengths)
    print(table)


if __name__ == "__main__":
    main()
