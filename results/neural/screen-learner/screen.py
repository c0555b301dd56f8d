"""The ninth session's screen of the MLP top level's learner (issue 31), seeds 0-9 only.

    TU=25 BOOT=max LR=1e-4 python screen.py Acrobot-v1 0 60 1.0 0.05 20 acro_flat_lr1

Arguments: env, max branching (0: neural flat), episodes, epsilon from, epsilon to, population
episodes to anneal over (a post_episodes hook on the mean episode count: the library's
--annealing-steps anneals by agent steps instead), output name. Environment variables patch the
built-in MLP top level's learner as it was then: TU (target copies every TU updates, then 250),
LR (Adam, then 1e-3), TE (an update every TE steps, 4), BOOT (sarsa or max), GAMMA (1).
``table.py`` prints the table in results/neural/README.md.
"""
import sys, time, json, numpy as np, torch
from trainers.config import TrainConfig
from trainers.population import PopulationTrainer
import os
import skillchain_torch.agents.pieces as pieces
_orig = pieces.ReplayTD
TU = int(os.environ.get("TU", "250")); LR = float(os.environ.get("LR", "1e-3")); TE = int(os.environ.get("TE", "4"))
def _patched(loss, optimizer, **kw):
    kw["target_update"] = TU; kw["train_every"] = TE
    for g in optimizer.param_groups: g["lr"] = LR
    return _orig(loss, optimizer, **kw)
pieces.ReplayTD = _patched
_origL = pieces.SMDPSarsaLoss
BOOT = os.environ.get("BOOT", "sarsa")
def _patchedL(*a, **kw):
    kw["bootstrap"] = BOOT
    return _origL(*a, **kw)
pieces.SMDPSarsaLoss = _patchedL
env, branching, episodes, eps0, eps1, decay_ep, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5]), float(sys.argv[6]), sys.argv[7]
cfg = TrainConfig(agent="skill-chaining", preset="paper", env=f"gymnasium:{env}", runs=10, episodes=episodes, seed=0,
                  max_branching=branching, gamma=float(os.environ.get("GAMMA", "1.0")), top_head="mlp", option_head="mlp", initiation="mlp")
tr = PopulationTrainer(cfg, out_dir=None)
def sched(trainer, batch=None):
    done = float(trainer.episodes_done.mean())
    trainer.agent.epsilon = eps1 + (eps0 - eps1) * max(0.0, 1 - done / decay_ep)
sched(tr)
tr.register_op("post_episodes", sched)
t = time.time(); tr.train(); w = time.time() - t
r = tr.returns
np.save(out + ".npy", r)
for a, b in [(0, 10), (10, 25), (25, 50), (50, 60), (50, 75), (75, 100)]:
    if b <= r.shape[1]:
        m = r[:, a:b].mean(1); print(f"{a+1}-{b}: {m.mean():.1f} ± {1.96*m.std(ddof=1)/np.sqrt(len(m)):.1f}")
print("wall", round(w), "steps", tr.agent_steps, "opts", getattr(tr, "n_options", None))
