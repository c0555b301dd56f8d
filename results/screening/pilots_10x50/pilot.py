"""Diagnose skill chaining: per-episode option usage, successes, timeouts."""
import sys, time, json, collections
import numpy as np, torch
from skillchain_torch.trainers import PopulationTrainer, TrainConfig
import functools
from skillchain_torch.options import OptionBank
args0 = dict(a.split("=") for a in sys.argv[1:])
_over = {}
if "cap" in args0:
    _over["capacity"] = int(args0["cap"])
if "oalpha" in args0:  # the options' Q-learning step size (paper 0.0005)
    _over["alpha"] = float(args0["oalpha"])
if _over:
    _b = OptionBank.build.__func__
    OptionBank.build = classmethod(lambda cls, *a, **k: _b(cls, *a, **{**k, **_over}))

args = dict(a.split("=") for a in sys.argv[1:])
import dataclasses
fields = {f.name: f for f in dataclasses.fields(TrainConfig)}
kw = dict(agent="skill-chaining", runs=10, episodes=50, seed=0, checkpoint_every=0)
alias = dict(pos="gestation_positives", start="initiation_start", cons="initiation_constrain", fb="failure_bootstrap", kn="keep_negatives")
for key, v in args.items():
    key = alias.get(key, key)
    if key in fields:
        d = fields[key].default
        kw[key] = (v in ("1", "true", "on")) if isinstance(d, bool) else type(d)(v) if d is not None and not isinstance(d, str) else (int(v) if key in ("runs","episodes","seed") else v)
cfg = TrainConfig(**kw)
print(cfg)
tr = PopulationTrainer(cfg)
ag = tr.agent
if "C" in args: ag.option_update.completion_reward = float(args["C"])
P, K = cfg.runs, cfg.slots
stats = collections.defaultdict(lambda: np.zeros(4, dtype=np.int64))  # (p, ep, k) -> steps, execs, succ, timeout
orig = ag.transition
budget = int(args.get("budget", 3_000_000))
steps = [0]
def transition(next_obs, reward, terminated, truncated, stepped):
    info = orig(next_obs, reward, terminated, truncated, stepped)
    opt = info["option"]; ended = info["decision_ended"]
    ep = ag.discovery.episode
    for p in (stepped & (opt >= 0)).nonzero()[:, 0].tolist():
        k = int(opt[p]); s = stats[(p, int(ep[p]), k)]
        s[0] += 1
        if bool(ended[p]):
            s[1] += 1
            if bool(info["reached"][p, k]): s[2] += 1
            elif int(info["duration"][p]) >= 250: s[3] += 1
    steps[0] += int(stepped.sum())
    if steps[0] > budget:
        raise KeyboardInterrupt
    return info
ag.transition = transition
t = time.time()
try:
    tr.train()
except KeyboardInterrupt:
    print("budget hit")
print("wall", time.time() - t, "steps", steps[0])
R = tr.returns; L = tr.lengths
np.save(args.get("out", "/tmp/diag/out") + "_returns.npy", R)
for p in range(P):
    n = int(tr.episodes_done[p]) if hasattr(tr, "episodes_done") else R.shape[1]
    line = []
    for e in range(R.shape[1]):
        if L[p, e] == 0: break
        os_ = [(k, stats[(p, e, k)]) for k in range(K) if (p, e, k) in stats]
        s = " ".join(f"o{k}:{v[0]}/{v[1]}/{v[2]}/{v[3]}" for k, v in os_)
        line.append(f"  ep{e} len={L[p,e]} R={R[p,e]:.0f} {s}")
    print(f"agent {p}"); print("\n".join(line))
print(ag.discovery.log[:0])
