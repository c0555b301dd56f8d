"""The ninth session's screen of the MLP top level's learner (issue 31), seeds 0-9 only.

    TU=25 BOOT=max LR=1e-4 python screen.py Acrobot-v1 0 60 1.0 0.05 20 acro_flat_lr1

Arguments: env, max branching (0: neural flat), episodes, epsilon from, epsilon to, population
episodes to anneal over (a post_episodes hook on the mean episode count: the library's
--annealing-steps anneals by agent steps instead), output name. Environment variables patch the
built-in MLP top level's learner as it was then: TU (target copies every TU updates, then 250),
LR (Adam, then 1e-3), TE (an update every TE steps, 4), BOOT (sarsa or max), GAMMA (1).
``table.py`` prints the table in results/neural/README.md.
"""

import os
import sys
import time

import numpy as np

import skillchain_torch.agents.pieces as pieces
from skillchain_torch.trainers.config.config import TrainConfig
from skillchain_torch.trainers.loop.population import PopulationTrainer

TU = int(os.environ.get("TU", "250"))
LR = float(os.environ.get("LR", "1e-3"))
TE = int(os.environ.get("TE", "4"))
BOOT = os.environ.get("BOOT", "sarsa")
GAMMA = float(os.environ.get("GAMMA", "1.0"))
_replay, _loss = pieces.ReplayTD, pieces.SMDPSarsaLoss


def _patched_replay(loss, optimizer, **kw):
    kw["target_update"], kw["train_every"] = TU, TE
    for group in optimizer.param_groups:
        group["lr"] = LR
    return _replay(loss, optimizer, **kw)


def _patched_loss(*args, **kw):
    kw["bootstrap"] = BOOT
    return _loss(*args, **kw)


pieces.ReplayTD, pieces.SMDPSarsaLoss = _patched_replay, _patched_loss


def main() -> None:
    env, branching, episodes = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    eps0, eps1, decay_episodes = float(sys.argv[4]), float(sys.argv[5]), float(sys.argv[6])
    out = sys.argv[7]
    cfg = TrainConfig(agent="skill-chaining", preset="paper", env=f"gymnasium:{env}", runs=10,
                      episodes=episodes, seed=0, max_branching=branching, gamma=GAMMA,
                      top_head="mlp", option_head="mlp", initiation="mlp")  # fmt: skip
    trainer = PopulationTrainer(cfg, out_dir=None)

    def anneal(trainer, batch=None):
        done = float(trainer.episodes_done.mean())
        trainer.agent.set_epsilon(eps1 + (eps0 - eps1) * max(0.0, 1 - done / decay_episodes))

    anneal(trainer)
    trainer.register_op("post_episodes", anneal)
    start = time.time()
    trainer.train()
    np.save(out + ".npy", trainer.returns)
    print("wall", round(time.time() - start), "agent steps", trainer.agent_steps)


if __name__ == "__main__":
    main()
