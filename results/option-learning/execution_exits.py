"""Do failing executions leave their option's initiation set, and which options fail?
(tenth session)

Trains ``RUNS`` agents of the default from ``SEED`` for 250 episodes and records every option
execution that ends from ``FIRST_EPISODE`` on: whether it leaves the option's own initiation set
(the set as it is when the execution ends, evaluated on the states the execution acted in), at
which step first, and the first step of a stay outside of 3, 5, 10 and 20 steps in a row; then
prints the shares for successes and timeouts.

    python results/option-learning/execution_exits.py RUNS SEED FIRST_EPISODE
    python results/option-learning/execution_exits.py 2 0 100  # screen/execution-exits/seeds0-1.npy

Columns: agent, episode, slot, success, duration, terminated, first step outside (-1: never),
share of steps inside, longest stay outside, first step of a stay of 3 / 5 / 10 / 20 (-1: none).
Screening seeds only.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from timeout_starts import on_execution_end  # this folder's script: the same hook, one place

from skillchain_torch.trainers import PopulationTrainer, TrainConfig

HERE = Path(__file__).resolve().parent
STAYS = (3, 5, 10, 20)


def record(records: list, first_episode: int) -> None:
    """Append a row per execution ending from ``first_episode`` on (the columns above)."""

    def row(rules, p, k, success, duration, terminated):
        if int(rules.episode[p]) < first_episode:
            return
        inside = rules.bank.classifier.contains_points(
            p, k, rules.trace.states[p, :min(duration, rules.trace.max_steps)])
        outside = (~inside).tolist()
        first_out = outside.index(True) if True in outside else -1
        run = longest = 0
        stay = dict.fromkeys(STAYS, -1)
        for i, out in enumerate(outside):
            run = run + 1 if out else 0
            longest = max(longest, run)
            for m in STAYS:
                if run >= m and stay[m] < 0:
                    stay[m] = i
        records.append((p, int(rules.episode[p]), k, success, duration, terminated, first_out,
                        float(inside.double().mean()), longest, *stay.values()))

    on_execution_end(row)


def main(runs: int, seed: int, first_episode: int) -> None:
    records: list = []
    record(records, first_episode)
    PopulationTrainer(TrainConfig(agent="skill-chaining", runs=runs, episodes=250,
                                  seed=seed)).train()  # fmt: skip
    r = np.array(records)
    out = HERE / "screen" / "execution-exits" / f"seeds{seed}-{seed + runs - 1}.npy"
    out.parent.mkdir(parents=True, exist_ok=True)
    np.save(out, r)
    success, timeout = r[r[:, 3] == 1], r[(r[:, 3] == 0) & (r[:, 4] >= 250)]
    print(f"executions {len(r)}, successes {len(success)}, timeouts {len(timeout)}")
    print(f"leave their set at some step: successes {(success[:, 6] >= 0).mean():.2f}, "
          f"timeouts {(timeout[:, 6] >= 0).mean():.2f}")
    for j, m in enumerate(STAYS, start=9):
        print(f"outside {m} steps in a row: successes {(success[:, j] >= 0).mean():.2f}, "
              f"timeouts {(timeout[:, j] >= 0).mean():.2f}")
    first = r[:, 2] == 0
    print(f"slot 0 (the first goal option): {first.mean():.2f} of executions, "
          f"{(first[(r[:, 3] == 0) & (r[:, 4] >= 250)]).mean():.2f} of timeouts")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:4]))
