"""The option banks a skill-chaining run held at a checkpoint, joined over its blocks into one
``options.pt`` (for ``--agent given-options --options``), for a run too slow to finish.

    python results/option-learning/bank_at_checkpoint.py OUT.pt \
        RUN/blocks/0-5/checkpoints/ckpt_000050.pt RUN/blocks/5-10/checkpoints/ckpt_000050.pt

Blocks are joined in the order given (give them in agent order: ``0-5`` before ``5-10``); every
per-agent tensor is concatenated along its first dimension, the shared bases are taken once.
"""

from __future__ import annotations

import sys

import torch

from skillchain_torch.options import OptionBank

SHARED = ("q_head.basis.coefficients", "classifier.features.exponents",
          "classifier.features.factor_index")  # fmt: skip


def main(out: str, paths: list[str]) -> None:
    states = [torch.load(p, weights_only=False)["agent"]["bank"] for p in paths]
    joined = {key: states[0][key] if key in SHARED else torch.cat([s[key] for s in states])
              for key in states[0]}  # fmt: skip
    population, slots = joined["status"].shape
    bank = OptionBank.build(population, slots)
    bank.load_state_dict(joined)  # refuses a tensor of the wrong shape
    bank.save(out)
    print(f"{out}: {population} agents x {slots} slots; options held "
          f"{bank.live().sum(1).tolist()}")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2:])
