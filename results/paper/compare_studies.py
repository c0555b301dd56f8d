"""The paper's claims side by side for several studies (each a ``skillchain reproduce paper``
folder with its ``report.json``): the default's, the paper preset's, the previous default's.

    python results/paper/compare_studies.py results/paper results/paper-preset results/paper-v3

The previous default's study, ``results/paper-v3``, is in git at 6835785 (removed from the tree),
restorable with ``git archive 6835785 results/paper-v3 | tar -x``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def claims(study: Path) -> dict[str, dict[str, tuple[str, bool]]]:
    """``{instance: {claim: (value, holds)}}`` of one study's report."""
    report = json.loads((study / "report.json").read_text())
    return {inst: {c["claim"]: (c["value"], c["holds"]) for c in rows}
            for inst, rows in report.items()}


def main(paths: list[str]) -> None:
    studies = [Path(p) for p in paths]
    tables = [claims(s) for s in studies]
    for inst in ("simple", "hard"):
        names = [c for t in tables for c in t.get(inst, {})]
        names = list(dict.fromkeys(names))
        if not names:
            continue
        print(f"\n{inst}\n")
        print("| claim | " + " | ".join(f"`{s}`" for s in studies) + " |")
        print("|---|" + "---|" * len(studies))
        for name in names:
            cells = []
            for t in tables:
                value, holds = t.get(inst, {}).get(name, ("not run", None))
                cells.append(value if holds is None else f"{value} ({'yes' if holds else 'no'})")
            print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
