"""The reader's path of one skill-chaining step on the torch path: which files it enters.

    python benchmarks/readers_path.py                 # 20 population steps after 60,000 agent steps
    python benchmarks/readers_path.py --steps 1 --warmup 20000

Issue 29 asks that one skill-chaining step, read top to bottom on the torch path, cross at most
8 files. This script measures it rather than guessing: it trains a small population (2 agents,
``pinball_simple_single``, seed 0) on the torch path everywhere (``native=False`` and
:func:`~skillchain_torch.backends.select.same_bits_kernels` off) until options exist, then
traces ``stepper.step`` + ``agent.observe`` for a few population steps with
:func:`sys.settrace` and prints every file of this repository that a Python call entered, in
the order first entered, with its call count, its role in DESIGN.md's reader's path, and how
many of its lines the step ran (what a reader must read, against what the file holds).

Example (a few seconds)::

    python benchmarks/readers_path.py --steps 1 --warmup 2000
"""

from __future__ import annotations

import argparse
import collections
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

ROLES = [  # (path prefix, role in DESIGN.md's reader's path)
    ("trainers/", "1 trainer"), ("envs/", "6 env"),
    ("skillchain_torch/agents/", "2 agent"), ("skillchain_torch/objectives/", "3 losses"),
    ("skillchain_torch/policies/", "2 agent (choice)"), ("skillchain_torch/modules/", "4 heads"),
    ("skillchain_torch/options/", "4 option set"), ("skillchain_torch/features/", "4 features"),
    ("skillchain_torch/discovery/", "5 discovery"), ("skillchain_torch/backends/", "backends"),
    ("skillchain_torch/", "utilities"),
]


def role(rel: str) -> str:
    return next((name for prefix, name in ROLES if rel.startswith(prefix)), "other")


def trace(steps: int, warmup: int) -> tuple[list[str], collections.Counter, dict[str, set]]:
    from skillchain_torch.backends.select import same_bits_kernels
    from trainers.config import TrainConfig
    from trainers.population import PopulationTrainer

    root = f"{ROOT}/"
    order: list[str] = []
    calls: collections.Counter = collections.Counter()
    lines: dict[str, set] = collections.defaultdict(set)  # the distinct lines a step executes

    def local(frame, event, arg):
        if event == "line":
            lines[frame.f_code.co_filename[len(root):]].add(frame.f_lineno)
        return local

    def profile(frame, event, arg):
        if event == "call":
            file = frame.f_code.co_filename
            if file.startswith(root) and "/.venv/" not in file:
                rel = file[len(root):]
                if rel not in calls:
                    order.append(rel)
                calls[rel] += 1
                return local
        return None

    with same_bits_kernels(False):
        config = TrainConfig(runs=2, episodes=30, map="pinball_simple_single", seed=0,
                             agent="skill-chaining")  # fmt: skip
        trainer = PopulationTrainer(config, native=False)
        trainer.train(max_agent_steps=warmup)
        action = trainer.agent.actions
        for _ in range(steps):
            sys.settrace(profile)  # calls, and the lines of this repository's frames
            obs, reward, ends = trainer.stepper.step(action)
            if ends is None:
                action = trainer.agent.observe(obs, reward)
            sys.settrace(None)
            if ends is not None:  # an episode ended: the step above is traced, stop there
                break
    return order, calls, lines


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20, help="population steps traced")
    parser.add_argument("--warmup", type=int, default=60_000, help="agent steps trained first")
    args = parser.parse_args(argv)
    order, calls, lines = trace(args.steps, args.warmup)
    print("| # | file | role | calls | lines run / in file |\n|---:|---|---|---:|---:|")
    total = {rel: sum(1 for _ in open(ROOT / rel)) for rel in order}
    for i, rel in enumerate(order, 1):
        print(f"| {i} | `{rel}` | {role(rel)} | {calls[rel]} | {len(lines[rel])} / {total[rel]} |")
    by_role = collections.Counter(role(rel) for rel in order)
    run = sum(len(lines[rel]) for rel in order)
    print(f"\n{len(order)} files entered (target: at most 8); by role: "
          + ", ".join(f"{name} {n}" for name, n in sorted(by_role.items()))
          + f"; {run:,} distinct lines run, in files of {sum(total.values()):,} lines")


if __name__ == "__main__":
    main()
