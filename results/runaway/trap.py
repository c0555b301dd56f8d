"""Trace one flat agent's long episode with its Q values, and draw where it spent it.

    python results/runaway/trap.py results/paper/simple/flat 13 249

re-runs the published agent alone to that episode (checked bit for bit against the run's
lengths), records per step the observation, the reward, Q(s, .) before the update and the
action, prints where the steps went and how the values fell, and writes
trap_o<order>_<agent>_<episode>.png beside this script (the path coloured by step, and Q(s, a)
against the step).

(The README's traces were made from ``results/paper-v3``, in git at 6835785 and restorable with
``git archive 6835785 results/paper-v3 | tar -x``; its ``simple/flat`` is the same run, config
and arrays, as ``results/paper/simple/flat``.)
"""
import dataclasses
import sys
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from skillchain_torch.envs.pinball.maps import load_map  # noqa: E402
from skillchain_torch.envs.pinball.render import plot_trajectories  # noqa: E402
from skillchain_torch.trainers.config.config import TrainConfig  # noqa: E402
from skillchain_torch.trainers.loop.population import PopulationTrainer  # noqa: E402

run, agent, episode = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
cfg = TrainConfig.load_json(f"{run}/config.json").resolved()
single = dataclasses.replace(cfg, runs=1, seed=cfg.seed + agent, episodes=episode,
                             checkpoint_every=0)
trainer = PopulationTrainer(single)
flat = trainer.agent
rows = []
observe = flat.observe


def traced(obs, reward):
    if trainer.episodes_done[0] != episode - 1:
        return observe(obs, reward)
    q = flat.q_values(flat.featurize(obs))[0]  # before this step's update (Q of each action)
    action = observe(obs, reward)
    rows.append([*obs[0].tolist(), float(reward[0]), *q.tolist(), int(action[0])])
    return action


flat.observe = traced
trainer.train()
same = np.array_equal(trainer.lengths[0], np.load(f"{run}/lengths.npy")[agent, :episode])
r = np.array(rows)
x, y, reward, q, act = r[:, 0], r[:, 1], r[:, 4], r[:, 5:10], r[:, 10].astype(int)
q_taken = q[np.arange(len(q)), act]
delta = reward[1:] + q_taken[1:] - q_taken[:-1]  # the reward of step t arrives with obs t + 1
print(f"prefix identical: {same}; episode length {trainer.lengths[0, -1]} ({len(r)} steps traced)")
print("actions (ACC_X, ACC_Y, DEC_X, DEC_Y, NONE):", np.bincount(act, minlength=5).tolist())
mid = slice(len(r) // 5, 4 * len(r) // 5)
print(f"middle three fifths: x {x[mid].min():.3f}-{x[mid].max():.3f}, "
      f"y {y[mid].min():.3f}-{y[mid].max():.3f}, median ({np.median(x[mid]):.3f}, "
      f"{np.median(y[mid]):.3f}); reward per step {reward[mid].mean():.2f}; mean TD error "
      f"{delta[mid].mean():.2f} (mean |TD error| {np.abs(delta[mid]).mean():.1f})")
slope = np.polyfit(np.arange(len(r))[mid], q.max(1)[mid], 1)[0]
print(f"max_a Q(s, a) falls by {-slope:.3f} per step over the middle (it starts at "
      f"{q.max(1)[:500].mean():.0f}, the last 500 steps {q.max(1)[-500:].mean():.0f})")

fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.8))
colors = plt.cm.viridis(np.linspace(0, 1, len(r) - 1))
plot_trajectories(load_map(cfg.map), [r[:, :2]], colors=[colors], ax=left, linewidth=0.6)
left.set_title(f"flat agent {agent}, episode {episode}: {len(r):,} steps (colour: step)")
right.plot(q_taken, lw=0.3, color="0.5", label="Q(s, a) of the action taken")
right.plot(np.convolve(q.max(1), np.ones(200) / 200, "valid"), color="C3",
           label="max_a Q(s, a), 200-step mean")
right.set_xlabel("step of the episode")
right.set_ylabel("value")
right.legend(loc="lower left", fontsize=8)
right.set_title(f"order {cfg.order}: values fall {-slope:.2f} per step; "
                f"each step costs {-reward[mid].mean():.1f}")
fig.tight_layout()
out = Path(__file__).with_name(f"trap_o{cfg.order}_{agent}_{episode}.png")
fig.savefig(out, dpi=110)
print("figure:", out.name)
