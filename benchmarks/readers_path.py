"""The reader's path of one skill-chaining step on the torch path: which files it enters.

    python benchmarks/readers_path.py                 # 20 population steps after 60,000 agent steps
    python benchmarks/readers_path.py --steps 1 --warmup 20000

Issue 51 asks that one skill-chaining step, read top to bottom on the torch path, enter at
most 6 core files (outside the pieces, the utilities and the env), and arrive back in one
already entered and left at most 8 times besides the algorithm's own file. This script
measures it: it trains a small population (2 agents, ``pinball_simple_single``, seed 0) on the
torch path everywhere (``native=False`` and
:func:`~skillchain_torch.backends.select.same_bits_kernels` off) until options exist, then
traces population steps as the trainer runs them (``trainer.train`` for one more step: its
loop, the collector, the env step and ``agent.observe``) with
:func:`sys.settrace` and prints every file of this repository that a Python call entered, in
the order first entered, with its call count, its role in DESIGN.md's reader's path, and how
many of its lines the step ran (what a reader must read, against what the file holds); then
issue 51's counts, from every call and return (:func:`sys.setprofile`).

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
    ("trainers/", "1 trainer"), ("skillchain_torch/collectors/", "1 collector"), ("envs/", "6 env"),
    ("skillchain_torch/agents/", "2 agent"), ("skillchain_torch/objectives/", "3 losses"),
    ("skillchain_torch/policies/", "2 agent (choice)"), ("skillchain_torch/modules/", "4 heads"),
    ("skillchain_torch/options/", "4 option set"), ("skillchain_torch/features/", "4 features"),
    ("skillchain_torch/discovery/", "5 discovery"), ("skillchain_torch/backends/", "backends"),
    ("skillchain_torch/", "utilities"),
]


def role(rel: str) -> str:
    return next((name for prefix, name in ROLES if rel.startswith(prefix)), "other")


PIECES = ("skillchain_torch/options/", "skillchain_torch/modules/", "skillchain_torch/features/",
          "skillchain_torch/objectives/", "skillchain_torch/policies/", "skillchain_torch/rng.py",
          "skillchain_torch/invariant.py", "envs/")


def is_core(rel: str) -> bool:
    """Issue 51's core: outside the user-replaceable pieces, the utilities and the env."""
    return not rel.startswith(PIECES)


def trace(steps: int, warmup: int):
    """Trace ``steps`` population steps after ``warmup`` agent steps of training.

    Returns ``(order, calls, lines, sequence)``: the files entered in the order first entered,
    their call counts, the distinct lines each ran (``sys.settrace``), and ``sequence``, the
    files in the order the step moved between them (``sys.setprofile``: a call puts the step in
    the callee's file, a return in the caller's; consecutive repeats merged), which issue 51's
    entries and re-arrivals are counted from."""
    from skillchain_torch.backends.select import same_bits_kernels
    from skillchain_torch.trainers.config.config import TrainConfig
    from skillchain_torch.trainers.loop.population import PopulationTrainer

    root = f"{ROOT}/"
    here = str(Path(__file__).resolve())
    order: list[str] = []
    calls: collections.Counter = collections.Counter()
    lines: dict[str, set] = collections.defaultdict(set)  # the distinct lines a step executes
    sequence: list[str] = []

    def ours(frame) -> str | None:
        file = frame.f_code.co_filename if frame is not None else ""
        if file.startswith(root) and "/.venv/" not in file and file != here:
            return file[len(root):]
        return None

    def local(frame, event, arg):
        if event == "line":
            lines[frame.f_code.co_filename[len(root):]].add(frame.f_lineno)
        return local

    def tracer(frame, event, arg):
        if event == "call" and (rel := ours(frame)) is not None:
            if rel not in calls:
                order.append(rel)
            calls[rel] += 1
            return local
        return None

    def profile(frame, event, arg):
        if event not in ("call", "return"):
            return
        rel = ours(frame if event == "call" else frame.f_back)
        if rel is not None and (not sequence or sequence[-1] != rel):
            sequence.append(rel)

    with same_bits_kernels(False):
        config = TrainConfig(runs=2, episodes=30, map="pinball_simple_single", seed=0,
                             agent="skill-chaining")  # fmt: skip
        trainer = PopulationTrainer(config, native=False)
        trainer.train(max_agent_steps=warmup)
        for _ in range(steps):
            done = int(trainer.episodes_done.sum())
            sys.settrace(tracer)  # calls, and the lines of this repository's frames
            sys.setprofile(profile)  # every call and return: the moves between files
            # One population step as the trainer runs it: its loop, the collector, the env
            # and the agent (the limit ends the batch after this step).
            trainer.train(max_agent_steps=trainer.agent_steps + 1)
            sys.setprofile(None)
            sys.settrace(None)
            if int(trainer.episodes_done.sum()) != done:  # an episode ended: stop there
                break
    return order, calls, lines, sequence


def report_arrivals(sequence: list[str]) -> None:
    """Issue 51's counts: core files entered, file entries, re-arrivals into core files."""
    again: collections.Counter = collections.Counter()
    seen: set[str] = set()
    for rel in sequence:
        if rel in seen:
            again[rel] += 1
        seen.add(rel)
    files = list(dict.fromkeys(sequence))
    core = [rel for rel in files if is_core(rel)]
    core_again = collections.Counter({rel: n for rel, n in again.items() if is_core(rel)})
    top = core_again.most_common(1)
    besides = sum(core_again.values()) - (top[0][1] if top else 0)
    print(f"\n{len(files)} files entered, {len(core)} of them core: {', '.join(core)}")
    print(f"{len(sequence)} file entries; arrivals into a core file already entered and left: "
          + ", ".join(f"{rel} {n}" for rel, n in core_again.most_common())
          + f"; {besides} besides the most-visited ({top[0][0] if top else '-'}) "
          "(issue 51's targets: at most 6 core files, at most 8 besides the most-visited)")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20, help="population steps traced")
    parser.add_argument("--warmup", type=int, default=60_000, help="agent steps trained first")
    args = parser.parse_args(argv)
    order, calls, lines, sequence = trace(args.steps, args.warmup)
    print("| # | file | role | calls | lines run / in file |\n|---:|---|---|---:|---:|")
    total = {rel: sum(1 for _ in open(ROOT / rel)) for rel in order}
    for i, rel in enumerate(order, 1):
        print(f"| {i} | `{rel}` | {role(rel)} | {calls[rel]} | {len(lines[rel])} / {total[rel]} |")
    by_role = collections.Counter(role(rel) for rel in order)
    run = sum(len(lines[rel]) for rel in order)
    print(f"\n{len(order)} files entered; by role: "
          + ", ".join(f"{name} {n}" for name, n in sorted(by_role.items()))
          + f"; {run:,} distinct lines run, in files of {sum(total.values()):,} lines")
    report_arrivals(sequence)


if __name__ == "__main__":
    main()
