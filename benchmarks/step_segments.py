"""Where a skill-chaining step's time goes: each call of the step timed inside a whole run.

    python benchmarks/step_segments.py                   # 10 x 100, seed 100 (the command's run)
    python benchmarks/step_segments.py --episodes 20     # a quick look

Trains ``skillchain train``'s run (``pinball_simple_single``, the default preset, compiled
kernels where built) in one process, with a timer around each call of the step that issue 51's
one compiled step would fuse: the memberships, the targets, the draws, the rest of the
transition (features, then the compiled step and its marshalling), discovery's record (the
executions that ended, the triggers, creation), and the collector's loop around them (the env
step, the batches). Prints one row per call: total seconds, calls, microseconds a call, and its
share of the training loop. Nested rows (indented) are inside the row above. The timers cost
about a microsecond a call; the totals are the run's, the shares are what to read.

Example (a few seconds)::

    python benchmarks/step_segments.py --runs 2 --episodes 2
"""

from __future__ import annotations

import argparse
import collections
import functools
import inspect
import time

from skillchain_torch.agents import hierarchical
from skillchain_torch.backends import compiled_discovery, compiled_step
from skillchain_torch.backends import hierarchical as hierarchical_kernels
from skillchain_torch.collectors import hierarchical as collectors
from skillchain_torch.discovery import skill_chaining
from skillchain_torch.rng import CounterRNG
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

TOTAL = collections.Counter()
CALLS = collections.Counter()

# (owner, attribute, row label): the order is the table's; two spaces nest a row in the last
SEGMENTS = (
    (collectors.HierarchicalCollector, "_steps", "collector loop (env steps, batches, agent)"),
    (hierarchical.HierarchicalAgent, "observe", "  agent.observe (the whole step)"),
    (hierarchical.HierarchicalAgent, "membership", "    memberships (sets, no-overlap rule)"),
    (hierarchical.SkillChainingAgent, "targets", "    targets (events, target indicator)"),
    (CounterRNG, "uniform", "    draws"),
    (compiled_step.CompiledStep, "transition", "    rest of the transition (features, step)"),
    (hierarchical_kernels, "transition", "      compiled step and its marshalling"),
    (skill_chaining.SkillChaining, "after_transition", "    discovery's record"),
    (skill_chaining.SkillChaining, "_finish_executions", "      executions that ended"),
    (compiled_discovery.CompiledSkillChaining, "_triggers", "      triggers and creation"),
    (skill_chaining.SkillChaining, "_create", "        creation"),
)


def timed(owner, name: str, label: str) -> None:
    """Wrap ``owner.name`` so that its calls add to ``TOTAL[label]`` and ``CALLS[label]``."""
    original = getattr(owner, name)

    @functools.wraps(original)
    def wrapper(*args, **kwargs):
        start = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            TOTAL[label] += time.perf_counter() - start
            CALLS[label] += 1

    # (a classmethod read from its class is bound: keep it a plain function there)
    setattr(owner, name, staticmethod(wrapper) if inspect.ismethod(original) else wrapper)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", default="pinball_simple_single")
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=100)
    args = parser.parse_args(argv)
    for owner, name, label in SEGMENTS:
        timed(owner, name, label)
    config = TrainConfig(agent="skill-chaining", map=args.map, runs=args.runs,
                         episodes=args.episodes, seed=args.seed)  # fmt: skip
    trainer = PopulationTrainer(config, out_dir=None, num_threads=1)
    start = time.perf_counter()
    trainer.train()
    loop = time.perf_counter() - start
    print(f"{args.runs} x {args.episodes} on {args.map}, seed {args.seed}: training {loop:.1f} s, "
          f"{trainer.global_step:,} population steps, {trainer.agent_steps:,} agent steps\n")
    print("| call | seconds | calls | us a call | share of training |")
    print("|---|---:|---:|---:|---:|")
    for _, _, label in SEGMENTS:
        n = CALLS[label]
        per = 1e6 * TOTAL[label] / n if n else 0.0
        name = label.strip()
        indent = "&nbsp;" * (len(label) - len(label.lstrip()))
        print(f"| {indent}{name} | {TOTAL[label]:.2f} | {n:,} | {per:.1f} | "
              f"{TOTAL[label] / loop:.1%} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
