"""Which options of a skill-chaining run are still usable: a census of its ``options.pt``.

An executable option whose initiation set holds no state is dead: it can never be chosen again.
Under the first reading ("true everywhere" until the first fit) a goal option that is first run
far from the goal, times out and is fitted on that single negative example dies this way. The
census counts, per agent, the executable options and those whose set is empty on a Figure-5
probe grid (positions on a grid, velocities in {-1, -1/2, 0, 1/2, 1}).

    python -m skillchain_torch.trainers.study.option_census runs/paper/simple/skill-chaining

Example:
    >>> from skillchain_torch.options import OptionBank, OptionStatus
    >>> bank = OptionBank.build(population=2, slots=2, order=1)
    >>> bank.status[0, 0] = int(OptionStatus.LEARNING)    # untrained: true everywhere
    >>> census(bank, resolution=4)["usable"].tolist()
    [1, 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

from skillchain_torch.options import OptionBank
from skillchain_torch.trainers.outputs.option_monitor import probe_observations

__all__ = ["census", "dead_agents", "main"]


@torch.no_grad()
def dead_agents(bank: OptionBank, agents=None, resolution: int = 12) -> list[int]:
    """The agents (of ``agents``, default all) none of whose executable options holds a state of
    the probe grid: agents that will likely never take an option. Stops at each agent's first
    usable option, so a healthy bank is checked in about one option per agent (:func:`census`
    visits every option, since it measures coverage). Pinball observations only (``[., 4]``).

    Example:
        >>> from skillchain_torch.options import OptionBank, OptionStatus
        >>> bank = OptionBank.build(population=2, slots=2, order=1)
        >>> bank.status[0, 0] = int(OptionStatus.LEARNING)    # untrained: true everywhere
        >>> dead_agents(bank, resolution=4)
        [1]
    """
    probe = probe_observations(resolution, dtype=bank.classifier.weight.dtype)
    executable = bank.executable().cpu().numpy()
    agents = range(executable.shape[0]) if agents is None else agents
    return [p for p in agents
            if not any(bool(bank.classifier.contains_points(p, k, probe).any())
                       for k in np.flatnonzero(executable[p]))]  # fmt: skip


@torch.no_grad()
def census(bank: OptionBank, resolution: int = 12) -> dict[str, np.ndarray]:
    """Per agent ``[P]``: ``executable`` options, ``dead`` ones (empty set on the probe grid),
    ``usable`` ones (the rest), and ``coverage``, the mean share of the grid their sets hold
    (over usable options; 0 when none)."""
    probe = probe_observations(resolution, dtype=bank.classifier.weight.dtype)
    executable = bank.executable().cpu().numpy()
    P, K = executable.shape
    dead = np.zeros(P, dtype=np.int64)
    usable = np.zeros(P, dtype=np.int64)
    coverage = np.zeros(P)
    for p in range(P):
        shares = []
        for k in range(K):
            if not executable[p, k]:
                continue
            share = float(bank.classifier.contains_points(p, k, probe).double().mean())
            if share == 0.0:
                dead[p] += 1
            else:
                usable[p] += 1
                shares.append(share)
        coverage[p] = float(np.mean(shares)) if shares else 0.0
    return {"executable": executable.sum(1), "dead": dead, "usable": usable,
            "coverage": coverage}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path, help="a skill-chaining run directory")
    parser.add_argument("--resolution", type=int, default=12)
    args = parser.parse_args(argv)
    path = args.run_dir / "options.pt"
    if not path.is_file():
        parser.error(f"{path} does not exist (a skill-chaining run writes it at the end)")
    c = census(OptionBank.load(path), args.resolution)
    P = len(c["usable"])
    none = int((c["usable"] == 0).sum())
    print(f"{path}: {P} agents; {none} ({100 * none / P:.0f}%) end with no usable option; "
          f"executable options per agent {c['executable'].mean():.2f}, dead "
          f"{c['dead'].mean():.2f}, usable {c['usable'].mean():.2f}; a usable option's set "
          f"holds {100 * c['coverage'][c['usable'] > 0].mean() if P > none else 0:.1f}% of the "
          f"probe grid on average")
    return 0


if __name__ == "__main__":
    sys.exit(main())
