"""How executions end under ``--end-outside-set`` (thirteenth session): success, timeout,
episode end, or left the option's learned set (which the run's ``option_outcomes.npy`` does not
count: such an execution is neither a success nor a failure).

Trains ``RUNS`` agents of the default (``end_outside_set="learned"``) on the simple instance
from ``SEED`` for 250 episodes, and classifies every execution that ends by what ended it, per
window of episodes. Screening seeds only.

    python results/option-learning/execution_ends.py RUNS SEED [MAP]
    python results/option-learning/execution_ends.py 4 0   # screen/execution-ends/seeds0-3.json
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import torch

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

HERE = Path(__file__).resolve().parent
WINDOWS = ((1, 25), (26, 50), (51, 100), (101, 200), (201, 250))
KINDS = ("success", "timeout", "episode_end", "left_set", "truncated")


def end_kinds(info: dict, option, terminated, truncated, max_option_steps: int):
    """What ended each row's execution this step, as an index into ``KINDS``; -1 where no
    execution ended. ``info`` is ``transition``'s monitoring dict and ``option [P]`` the option
    in force during the step (-1: none)."""
    ended = info["decision_ended"] & (option >= 0)
    hit = info["reached"].gather(1, option.clamp(min=0)[:, None])[:, 0]
    term, trunc = terminated.to(torch.bool), truncated.to(torch.bool)
    kind = torch.where(hit, 0, torch.where(info["duration"] >= max_option_steps, 1,
                       torch.where(term, 2, torch.where(trunc, 4, 3))))  # fmt: skip
    return torch.where(ended, kind, -1)


def main(runs: int, seed: int, map_name: str = "pinball_simple_single") -> dict:
    counts = {f"{a}-{b}": dict.fromkeys(KINDS, 0) for a, b in WINDOWS}
    transition = SkillChainingAgent.transition
    trainer = None

    def counted(self, next_obs, reward, terminated, truncated, stepped):
        option = self.option.clone()  # the option in force during this step
        info = transition(self, next_obs, reward, terminated, truncated, stepped)
        kind = end_kinds(info, option, terminated, truncated, self.max_option_steps)
        if bool((kind >= 0).any()):
            episode = self.discovery.episode + 1  # (1-based, the episode in progress)
            for p in (kind >= 0).nonzero()[:, 0].tolist():
                e = int(episode[p])
                window = next((f"{a}-{b}" for a, b in WINDOWS if a <= e <= b), None)
                if window is not None:
                    counts[window][KINDS[int(kind[p])]] += 1
        return info

    SkillChainingAgent.transition = counted
    try:
        cfg = TrainConfig(agent="skill-chaining", map=map_name, runs=runs, episodes=250,
                          seed=seed)
        trainer = PopulationTrainer(cfg)
        trainer.train()
    finally:
        SkillChainingAgent.transition = transition
    return counts


if __name__ == "__main__":
    runs, seed = int(sys.argv[1]), int(sys.argv[2])
    map_name = sys.argv[3] if len(sys.argv) > 3 else "pinball_simple_single"
    result = main(runs, seed, map_name)
    out = HERE / "screen" / "execution-ends" / f"{map_name}-seeds{seed}-{seed + runs - 1}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1) + "\n")
    for window, c in result.items():
        total = sum(c.values())
        print(window, total, " ".join(f"{k} {v / max(total, 1):.3f}" for k, v in c.items()))
