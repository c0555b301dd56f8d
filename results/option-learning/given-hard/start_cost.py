"""Where the given options' first episodes on the hard instance spend their steps.

    python results/option-learning/given-hard/start_cost.py BANK --runs 10 --episodes 1 \
        [--end-outside-set off] [--seed 1000] [--out FILE.json]

Issue 30 / results/paper/DISCUSSION.md: given options start far below the discoverers' final
level on ``pinball_hard_two_starts``, and worse under the default (executions end where they
leave a converged set) than under the previous default. Two explanations compete:

* coverage: the tree does not reach the start states, so the agent begins as a flat learner
  and pays a flat learner's cost until it first enters an option's set;
* hand-back: an execution that ends where it leaves its set returns control to a top level
  that has learned nothing yet, far from where the option would have taken it.

This script runs the given-options agent (agent p takes saved agent p's bank, as the study
does) for a few episodes and splits every agent step by what controls it: an option, a
primitive where some option's set holds the state, or a primitive where none does. It also
counts how each execution ended: its target, a timeout, leaving its set, or the episode's end.
No learning rule is changed; the agent's ``transition`` is wrapped to read its monitoring dict.

Example (a minute)::

    python results/option-learning/given-hard/start_cost.py \
        results/option-learning/confirm-hard/end-outside-learned/options.pt --runs 2
"""

from __future__ import annotations

import argparse
import importlib.util
import json
from pathlib import Path

import torch

from skillchain_torch.trainers.config.config import TrainConfig
from skillchain_torch.trainers.loop.population import PopulationTrainer


def _script(name: str):
    """``results/option-learning/<name>.py`` (the study's scripts), loaded as a module."""
    path = Path(__file__).resolve().parents[1] / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_ends = _script("execution_ends")
END_KINDS, end_kinds = _ends.KINDS, _ends.end_kinds

KINDS = ("option", "primitive_covered", "primitive_uncovered")
# execution_ends.KINDS under this script's names (terminated and truncated: one episode end)
ENDS = {"success": "target", "timeout": "timeout", "left_set": "left_set",
        "episode_end": "episode_end", "truncated": "episode_end"}  # fmt: skip


def measure(bank: str, runs: int, episodes: int, seed: int, end_outside_set: str | None) -> dict:
    config = TrainConfig(agent="given-options", map="pinball_hard_two_starts", runs=runs,
                         episodes=episodes, seed=seed, options=bank, options_agent=None,
                         end_outside_set=end_outside_set)  # fmt: skip
    trainer = PopulationTrainer(config)
    agent = trainer.agent
    steps = {k: torch.zeros(runs, dtype=torch.int64) for k in KINDS}
    ends = {k: torch.zeros(runs, dtype=torch.int64) for k in dict.fromkeys(ENDS.values())}
    inner = agent.transition
    rows = torch.arange(agent.population)  # transition's rows are agents; ``stepped`` masks

    def transition(next_obs, reward, terminated, truncated, stepped):
        covered = agent.contains.any(1)  # some option's set holds s (before this step)
        info = inner(next_obs, reward, terminated, truncated, stepped)
        option = info["option"]  # in force during this step
        kind = torch.where(option >= 0, 0, torch.where(covered, 1, 2))
        for i, name in enumerate(KINDS):
            steps[name].index_add_(0, rows, (stepped & (kind == i)).long())
        end = end_kinds(info, option, terminated, truncated, agent.max_option_steps)
        for i, name in enumerate(END_KINDS):
            ends[ENDS[name]].index_add_(0, rows, (stepped & (end == i)).long())
        return info

    agent.transition = transition
    trainer.train()
    return {
        "config": {
            "bank": bank,
            "runs": runs,
            "episodes": episodes,
            "seed": seed,
            "end_outside_set": agent.leave_from is not None,
        },
        "steps": {k: v.tolist() for k, v in steps.items()},
        "execution_ends": {k: v.tolist() for k, v in ends.items()},
        "returns": trainer.returns.tolist(),
        "lengths": trainer.lengths.tolist(),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bank")
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--episodes", type=int, default=1)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--end-outside-set", default=None)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    result = measure(args.bank, args.runs, args.episodes, args.seed, args.end_outside_set)
    total = {k: sum(v) for k, v in result["steps"].items()}
    n = sum(total.values())
    print(f"{n:,} agent steps: " + ", ".join(f"{k} {v / n:.1%}" for k, v in total.items()))
    ends = {k: sum(v) for k, v in result["execution_ends"].items()}
    m = max(1, sum(ends.values()))
    print(
        f"{sum(ends.values()):,} executions ended: "
        + ", ".join(f"{k} {v / m:.1%}" for k, v in ends.items())
    )
    if args.out:
        args.out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
