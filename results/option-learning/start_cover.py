"""Does an agent's option tree reach the hard instance's start states? For each run folder (with
its ``options.pt``, which a run writes and this repository does not keep), how many agents hold an
executable option (learning or learned; a gestating option's set is not yet its own) whose
initiation set contains each start state at rest, (0.055, 0.95) and
(0.945, 0.95) with velocity descriptor 0.5 (the Java descriptor ``(v + 1) / 2`` of v = 0).

    python results/option-learning/start_cover.py results/option-learning/pilot-hard/k12 ...
"""

from __future__ import annotations

import sys

import numpy as np
import torch

from skillchain_torch.options import OptionBank

STARTS = ((0.055, 0.95), (0.945, 0.95))  # pinball_hard_two_starts.cfg


def covered(run: str) -> list[int]:
    """Agents of ``run`` whose executable options' own sets hold each start state."""
    bank = OptionBank.load(f"{run}/options.pt")
    counts = []
    for x, y in STARTS:
        obs = torch.tensor([[x, y, 0.5, 0.5]] * bank.population, dtype=torch.float64)
        counts.append(int((bank.classifier.contains(obs) & bank.executable()).any(1).sum()))
    return counts


def main() -> None:
    for run in sys.argv[1:]:
        held = np.load(f"{run}/n_options.npy")[:, -1]
        left, right = covered(run)
        print(f"{run}: options at the end {held.tolist()}; start states covered in "
              f"{left} (left) and {right} (right) of {len(held)} agents")


if __name__ == "__main__":
    main()
