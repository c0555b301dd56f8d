"""48 slots against the default's 12 on the hard instance, at full size, paired by seed (issue 30).

Stacks the 48-slot blocks ``end-outside-k48-seeds*`` (seeds 1000 on, in order, checked to follow
on) and pairs them with the first agents of ``results/paper-k12/hard`` (12 slots, the study's
hard arm until the default became 48 there) and ``results/paper/hard/flat``: mean
return per window and 95% t intervals over runs (``*``: excludes 0); the last block alone as the
fresh-seed check; the sd ratio against flat over 201-250; executions' outcomes; banks filled.

    python results/option-learning/confirm-hard/k48_table.py
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.intervals import mean_ci

HERE = Path(__file__).resolve().parent


def _script(name: str):
    """``results/option-learning/<name>.py`` (this study's scripts), loaded as a module."""
    spec = importlib.util.spec_from_file_location(name, HERE.parent / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


compare = _script("compare")
WINDOWS = compare.WINDOWS


def fmt(mean: float, half: float) -> str:
    """``slots.fmt``: the interval, starred where it excludes 0."""
    return compare.fmt(mean, half) + (" *" if abs(mean) > half else "")

PAPER = HERE.parents[1] / "paper" / "hard"  # flat
K12 = HERE.parents[1] / "paper-k12" / "hard"  # the default's 12 slots, same seeds


def blocks() -> list[Path]:
    finished = [p for p in HERE.glob("end-outside-k48-seeds*") if (p / "returns.npy").exists()]
    configs = {b: json.loads((b / "config.json").read_text()) for b in finished}
    found = sorted(finished, key=lambda b: configs[b]["seed"])
    seed = 1000
    for b in found:
        config = configs[b]
        if config["seed"] != seed or config["slots"] != 48:
            sys.exit(f"{b}/config.json: seed {config['seed']}, slots {config['slots']}; "
                     f"expected seed {seed} and 48 slots")
        seed += config["runs"]
    return found


def main() -> None:
    found = blocks()
    load = lambda name: np.concatenate([np.load(b / name) for b in found])  # noqa: E731
    k48 = load("returns.npy")
    n = k48.shape[0]
    last = np.load(found[-1] / "returns.npy").shape[0]
    k12 = np.load(K12 / "skill-chaining/returns.npy")[:n]
    flat = np.load(PAPER / "flat/returns.npy")[:n]

    def cell(d: np.ndarray) -> str:
        return fmt(*mean_ci(d))

    def w(r: np.ndarray, a: int, b: int) -> np.ndarray:
        return r[:, a - 1:b].mean(1)

    print(f"{n} runs (seeds 1000-{999 + n}); the last block alone: {last} runs\n")
    print(f"| episodes | 12 slots | 48 - 12 slots | 48 - 12, last {last} seeds | 48 slots - flat |"
          " 12 slots - flat |\n|---|---:|---|---|---|---|")
    for a, b in WINDOWS:
        print(f"| {a}-{b} | {w(k12, a, b).mean():,.0f} | {cell(w(k48, a, b) - w(k12, a, b))} | "
              f"{cell(w(k48, a, b)[-last:] - w(k12, a, b)[-last:])} | "
              f"{cell(w(k48, a, b) - w(flat, a, b))} | {cell(w(k12, a, b) - w(flat, a, b))} |")
    sd = lambda r: w(r, 201, 250).std(ddof=1)  # noqa: E731
    print(f"\nsd over runs of the 201-250 mean / flat's: 48 slots {sd(k48) / sd(flat):.2f}, "
          f"12 slots {sd(k12) / sd(flat):.2f}")
    for name, outcomes in (("48", load("option_outcomes.npy")),
                           ("12", np.load(K12 / "skill-chaining/option_outcomes.npy")[:n])):
        s, t, e = outcomes[:, 200:].sum((0, 1))
        print(f"{name} slots, executions ended over 201-250: {s:,} at the target, {t:,} timeouts,"
              f" {e:,} at the episode's end")
    held = load("n_options.npy")
    full = held.max(1) >= 48
    first = [int(np.argmax(h >= 48)) + 1 for h in held[full]]
    print(f"48 slots: {int(full.sum())}/{n} banks fill, at a median of episode "
          f"{np.median(first):.0f}")


if __name__ == "__main__":
    main()
