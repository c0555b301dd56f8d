"""The raw arrays of a run stopped before its end, from each block's latest checkpoint, so that a
partial run's numbers can be committed and re-read (its checkpoints are not committed).

    python results/option-learning/checkpoint_arrays.py RUN

Writes into RUN:
- ``partial_returns.npy``, ``partial_lengths.npy``: ``[runs, episodes]`` float64, NaN after each
  agent's last finished episode;
- ``partial.json``: per agent the episodes finished, options held and the episode each option
  was created (-1: empty slot), and which checkpoint each block was read from.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import torch


def main(run: Path) -> None:
    returns, lengths, done, held, created, read = [], [], [], [], [], {}
    blocks = sorted((run / "blocks").iterdir(), key=lambda p: int(p.name.split("-")[0]))
    for block in blocks:
        latest = sorted((block / "checkpoints").glob("ckpt_*.pt"))[-1]
        state = torch.load(latest, weights_only=False)
        trainer, bank = state["trainer"], state["agent"]["bank"]
        finished = trainer["episodes_done"].numpy()
        for name, out in (("returns", returns), ("lengths", lengths)):
            array = trainer[name].numpy().astype(np.float64)
            for p, n in enumerate(finished):
                array[p, n:] = np.nan
            out.append(array)
        done += finished.tolist()
        held += (bank["status"] != 0).sum(1).tolist()
        created += torch.where(bank["status"] != 0, bank["created_episode"], -1).tolist()
        read[block.name] = latest.name
    np.save(run / "partial_returns.npy", np.concatenate(returns))
    np.save(run / "partial_lengths.npy", np.concatenate(lengths))
    (run / "partial.json").write_text(json.dumps(
        {"checkpoints": read, "episodes_done": done, "options_held": held,
         "created_episode": created}, indent=None) + "\n")  # fmt: skip
    print(f"{run}: episodes finished {done}; options held {held}")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(Path(sys.argv[1]))
