"""Window means of one cell against another (Welch 95% intervals), for the screening notes.

    python results/screening/versus.py results/screening/simple_P20_E250_seed0/{A,B} [--flat DIR]

Prints, per episode window, ``A - B`` (and ``A - flat``, ``B - flat`` with ``--flat``) as
``mean +- half-width``, starred where the interval excludes zero. A cell that stopped early
(a partial run: its last checkpoint) is compared over the episodes every agent completed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from screen import WINDOWS, load_cell  # (this script's folder is on sys.path)

from skillchain_torch.trainers.study.intervals import diff_ci

WINDOWS_250 = WINDOWS[:-1] + ((151, 200), (201, 250))


def _load(d: Path):
    """A run directory's arrays (a finished run or its last checkpoint), or the arrays a
    screen report committed for a stopped cell."""
    cell = load_cell(d)
    if cell is None and (d / "returns.npy").exists():
        R = np.load(d / "returns.npy")
        return R, np.load(d / "lengths.npy"), f"stopped after {R.shape[1]} episodes"
    return cell


def _fmt(d: float, h: float) -> str:
    return f"{d:+,.0f} ± {h:,.0f}" + (" *" if abs(d) > h else "")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("a")
    p.add_argument("b")
    p.add_argument("--flat", default=None)
    args = p.parse_args(argv)
    cells = {"a": _load(Path(args.a)), "b": _load(Path(args.b))}
    if args.flat:
        cells["flat"] = _load(Path(args.flat))
    for name, cell in cells.items():
        if cell is None:
            sys.exit(f"{getattr(args, name)}: no returns.npy and no checkpoint")
    R = {k: v[0] for k, v in cells.items()}
    head = ["episodes", "A - B"] + (["A - flat", "B - flat"] if args.flat else [])
    print("| " + " | ".join(head) + " |\n|" + "---|" * len(head))
    for first, last in WINDOWS_250:
        if last > min(r.shape[1] for r in R.values()):
            break
        w = {k: r[:, first - 1:last].mean(1) for k, r in R.items()}
        row = [f"{first}-{last}", _fmt(*diff_ci(w["a"], w["b"]))]
        if args.flat:
            row += [_fmt(*diff_ci(w["a"], w["flat"])), _fmt(*diff_ci(w["b"], w["flat"]))]
        print("| " + " | ".join(row) + " |")
    for name, cell in cells.items():
        if cell[2]:
            print(f"({name}: {cell[2]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
