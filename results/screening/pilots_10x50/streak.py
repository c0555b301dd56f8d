import sys, numpy as np, torch
from skillchain_torch.trainers import PopulationTrainer, TrainConfig
from skillchain_torch.options import OptionBank
args0 = dict(a.split("=") for a in sys.argv[1:])
if "cap" in args0:
    _b = OptionBank.build.__func__
    OptionBank.build = classmethod(lambda cls, *a, **k: _b(cls, *a, **{**k, "capacity": int(args0["cap"])}))
args = dict(a.split("=") for a in sys.argv[1:])
seed, E, target_ep = int(args.get("seed", 0)), int(args.get("episodes", 41)), int(args.get("ep", 40))
cfg = TrainConfig(agent="skill-chaining", runs=1, episodes=E, seed=seed, checkpoint_every=0,
                  gestation_positives=int(args.get("pos", 20)), initiation_start=args.get("start", "fitted"),
                  initiation_constrain=args.get("cons", "start"), failure_bootstrap=args.get("fb", "primitives"),
                  keep_negatives=args.get("kn", "on") == "on")
tr = PopulationTrainer(cfg); ag = tr.agent
orig = ag.transition
cur = {}
def fmt(s): return "(" + ",".join(f"{v:.3f}" for v in s.tolist()) + ")"
def transition(next_obs, reward, terminated, truncated, stepped):
    ep = int(ag.discovery.episode[0])
    opt_before = int(ag.option[0]); dur = int(ag.duration[0])
    if ep == target_ep and opt_before >= 0 and dur == 0:
        s = ag.obs[0]; q = ag.q_head(ag.features(ag.obs))[0]
        cur.update(start=s.clone(), q=q.clone(), k=opt_before,
                   contains=ag.contains[0].clone())
    dec_before = int(ag.decision[0]); s_before = ag.obs[0].clone()
    info = orig(next_obs, reward, terminated, truncated, stepped)
    if ep == target_ep and opt_before < 0 and args0.get("prim") == "1":
        print(f"   prim {dec_before} at {fmt(s_before)} avail {ag.contains[0].nonzero().flatten().tolist()} Q={[round(v) for v in ag.last_q[0].tolist()]}")
    if ep == target_ep and opt_before >= 0 and bool(info["decision_ended"][0]):
        k = opt_before; q0 = cur["q"]; qn = ag.last_q[0]
        print(f"o{k} start {fmt(cur['start'])} Q(s,o)={q0[5+k]:.0f} maxQprim={q0[:5].max():.0f} "
              f"-> dur {int(info['duration'][0])} R={float(info['decision_return'][0]):.0f} "
              f"reached={bool(info['reached'][0,k])} end {fmt(next_obs[0])} maxQprim'={qn[:5].max():.0f} "
              f"Q(s',o)={qn[5+k]:.0f} d'={int(ag.decision[0])} delta={float(info['smdp_delta'][0]):.0f}")
    return info
ag.transition = transition
tr.train()
print(tr.lengths[0, target_ep-2:target_ep+1], tr.returns[0, target_ep-2:target_ep+1])
bank = ag.bank
clf = bank.classifier
for k in range(bank.slots):
    if not bool(bank.live()[0, k]): continue
    n = int(clf.count[0, k]); ex = clf.examples[0, k, :n]; lab = clf.labels[0, k, :n]
    code = bank.q_head.basis(ex)
    w = bank.q_head.weight[0, k]  # [A, Fo]
    q = code @ w.T
    print(f"slot {k} status {int(bank.status[0,k])} parent {int(bank.parent[0,k])} ex {n} pos {int(lab.sum())} "
          f"Qopt range [{q.min():.0f}, {q.max():.0f}] mean {q.mean():.0f} argmax hist {torch.bincount(q.argmax(1), minlength=5).tolist()} |w| {w.abs().max():.1f}")
