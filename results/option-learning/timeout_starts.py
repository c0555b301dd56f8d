"""Where do the late timeouts of skill chaining's options start? (issue 30's late gap)

Trains a few agents of the default (screening seeds), records every option execution as it ends
(agent, episode, slot, success, duration, the distance of its start state to the nearest stored
negative and positive example of its slot, and the start state), and prints how the timeouts of
episodes 101-250 differ from the successes.

    python results/option-learning/timeout_starts.py NAME [train flags...]
    python results/option-learning/timeout_starts.py store-failures --store-failures on

Writes ``screen/timeout-starts/NAME.npy`` (one row per execution, the columns above). Seeds 0-3
(screening seeds, never the evidence).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

from skillchain_torch.discovery import SkillChaining
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

HERE = Path(__file__).resolve().parent
COLUMNS = ("agent", "episode", "slot", "success", "duration", "terminated", "nearest_negative",
           "nearest_positive", "x", "y", "xdot", "ydot")  # fmt: skip


def on_execution_end(row) -> None:
    """Wrap discovery's end-of-execution rule: ``row(rules, p, k, success, duration,
    terminated)`` for each agent ``p`` whose execution of slot ``k`` ends, before the rule runs
    (the slot's stored examples and ``rules.trace`` still as the execution left them)."""
    finish = SkillChaining._finish_executions

    def recorded(self, option, reached, duration, ended, terminated):
        rows = (ended & (option >= 0)).nonzero()[:, 0]
        slot = option.clamp(min=0)
        hit = reached.gather(1, slot[:, None])[:, 0]
        for p in rows.tolist():
            row(self, p, int(slot[p]), int(hit[p]), int(duration[p]), int(terminated[p]))
        return finish(self, option, reached, duration, ended, terminated)

    SkillChaining._finish_executions = recorded


def record_executions(records: list) -> None:
    """Append a row per ended execution (the columns ``COLUMNS``) to ``records``."""

    def row(rules, p, k, success, duration, terminated):
        clf = rules.bank.classifier
        start, n = rules.trace.states[p, 0], int(clf.count[p, k])
        labels, examples = clf.labels[p, k, :n], clf.examples[p, k, :n]
        distance = torch.cdist(start[None], examples)[0]
        nearest = [float(distance[m].min()) if bool(m.any()) else np.inf
                   for m in (~labels, labels)]  # fmt: skip
        records.append((p, int(rules.episode[p]), k, success, duration, terminated, *nearest,
                        *start.tolist()))  # fmt: skip

    on_execution_end(row)


def main(name: str, flags: list[str]) -> None:
    fields = {}
    for flag, value in zip(flags[::2], flags[1::2]):
        field = flag.lstrip("-").replace("-", "_")
        fields[field] = {"on": True, "off": False}.get(value, value)
    records: list = []
    record_executions(records)
    trainer = PopulationTrainer(TrainConfig(agent="skill-chaining", runs=4, episodes=250, seed=0,
                                            **fields))  # fmt: skip
    trainer.train()
    rows = np.array(records, dtype=np.float64)
    out = HERE / "screen" / "timeout-starts"
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / f"{name}.npy", rows)
    late = rows[rows[:, 1] >= 100]
    timeout = late[(late[:, 3] == 0) & (late[:, 4] >= 250)]
    success = late[late[:, 3] == 1]
    print(f"{name}: episodes 101-250, {len(late)} executions, {len(timeout)} timeouts; "
          f"mean return 201-250 {trainer.returns[:, 200:].mean():,.0f}")
    for label, part in (("timeouts", timeout), ("successes", success)):
        negative, positive = np.median(part[:, 6]), np.median(part[:, 7])
        print(f"  {label}: start to the nearest stored negative, median {negative:.3f}; "
              f"to the nearest stored positive {positive:.3f}")
    for rule, test in (("within 0.02 of a negative", lambda r: r[:, 6] < 0.02),
                       ("nearer a negative than any positive", lambda r: r[:, 6] < r[:, 7])):
        print(f"  {rule}: {test(timeout).mean():.2f} of timeout starts, "
              f"{test(success).mean():.2f} of success starts")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
