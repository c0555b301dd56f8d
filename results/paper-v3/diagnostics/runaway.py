"""Trace one training episode of one published agent: re-run it alone to that episode and
record, per step, its position, the option executing (-1: primitive) and the action.

    python results/paper/diagnostics/runaway.py results/paper/simple/skill-chaining 84 225
    python results/paper/diagnostics/runaway.py results/paper/simple/flat 13 249

prints where the episode's steps went and saves the trace to runs/diag/trace_<agent>_<episode>.npy.
"""
import dataclasses
import sys
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.config.config import TrainConfig
from skillchain_torch.trainers.loop.population import PopulationTrainer

run, agent, episode = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
cfg = TrainConfig.load_json(f"{run}/config.json").resolved()
single = dataclasses.replace(cfg, runs=1, seed=cfg.seed + agent, episodes=episode,
                             checkpoint_every=0)
t = PopulationTrainer(single)
trace = []
observe = t.agent.observe
def traced(obs, reward):
    out = observe(obs, reward)
    if t.episodes_done[0] == episode - 1:
        option = getattr(t.agent, "option", None)  # a flat agent has none: all primitive
        decision = getattr(t.agent, "decision", t.agent.actions)
        trace.append([*obs[0].tolist(), -1 if option is None else int(option[0]),
                      int(decision[0])])
    return out
t.agent.observe = traced
t.train()
pub = np.load(f"{run}/lengths.npy")[agent, :episode]
print("prefix identical:", np.array_equal(t.lengths[0], pub), "episode length", t.lengths[0, -1])
tr = np.array(trace)
Path("runs/diag").mkdir(parents=True, exist_ok=True)
np.save(f"runs/diag/trace_{agent}_{episode}.npy", tr)
opt = tr[:, 4].astype(int)
share = {int(k): round(float((opt == k).mean()), 3) for k in np.unique(opt)}
print("share of steps by option (-1: primitives):", share)
# where: 0.05 grid cells visited most
cells = np.floor(tr[:, :2] / 0.05).astype(int)
u, c = np.unique(cells, axis=0, return_counts=True)
top = np.argsort(-c)[:6]
print("most visited 0.05 cells (x, y, steps):",
      [(round(u[i, 0] * 0.05, 2), round(u[i, 1] * 0.05, 2), int(c[i])) for i in top])
# stretches of one executing option (-1: primitive actions)
cuts = np.flatnonzero(np.diff(opt) != 0) + 1
stretches = {}
for piece in np.split(opt, cuts):
    stretches.setdefault(int(piece[0]), []).append(len(piece))
for k, lens in sorted(stretches.items()):
    name = "primitives" if k < 0 else f"option {k}"
    print(f"{name}: {len(lens)} stretches, longest {max(lens)}, {sum(lens)} steps")
