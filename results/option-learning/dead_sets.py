"""How much of the state box each option's initiation set holds at the end of a run, and what
its store holds: why the paper preset's options stop being executed (twelfth session).

    python results/option-learning/dead_sets.py results/option-learning/confirm-hard/paper-k48

Reads ``RUN/options.pt`` (not committed: rebuilt by the run; the numbers it printed are in
``RUN/dead_sets.json``), samples 4,000 states uniformly in the unit box per agent (seed 0) and
counts, per live slot, the share the classifier's logit puts inside (``logit > 0``, before the
no-overlap narrowing), the stored examples and the stored positives.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import torch

from skillchain_torch.options import OptionBank, OptionStatus


def main(run: Path) -> dict:
    bank = OptionBank.load(run / "options.pt")
    live = bank.live()
    points = torch.rand(bank.population, 4000, bank.obs_dim, dtype=torch.float64,
                        generator=torch.Generator().manual_seed(0))  # fmt: skip
    with torch.no_grad():
        inside = (bank.classifier.logit(points) > 0).double().mean(1)  # [P, K]
    # an untrained slot contains everything (InitiationClassifier.contains), whatever its logit
    inside = torch.where(bank.classifier.trained, inside, torch.ones_like(inside))
    clf = bank.classifier
    positives = clf.labels.sum(-1)
    summary = {
        "agents": bank.population,
        "options": int(live.sum()),
        "mean_share_inside": float(inside[live].mean()),
        "options_holding_over_1pct": int((inside[live] > 0.01).sum()),
        "mean_stored": float(clf.count[live].double().mean()),
        "options_with_a_positive": int((positives[live] > 0).sum()),
        "status_counts": {OptionStatus(s).name: int((bank.status[live] == s).sum())
                          for s in bank.status[live].unique().tolist()},
    }
    (run / "dead_sets.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


if __name__ == "__main__":
    print(json.dumps(main(Path(sys.argv[1])), indent=2))
