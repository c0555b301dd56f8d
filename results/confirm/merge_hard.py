"""Lay the hard block's seed parts out as one run per arm (issue 52's hard confirmation block).

    python results/confirm/merge_hard.py results/confirm/hard-5000x100

``run_hard.sh`` trains each arm in parts ``ARM/parts/A-B`` (agents ``[A, B)`` of the arm, the
run of ``B - A`` agents seeded ``5000 + A``: the seed contract makes them the arm's agents, bit
for bit). This stacks the finished parts that cover agents ``0 .. N`` without a gap into
``ARM/*.npy`` (the per-run arrays ``table.py`` reads) and writes ``ARM/parts.json``: each
part's seeds, wall time, agent steps and commit. A part still running is left out; the arm
then holds the agents before it. The parts' own folders keep their configs and logs.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

ARRAYS = ("returns.npy", "lengths.npy", "n_options.npy", "option_outcomes.npy")


def finished_parts(arm: Path) -> list[tuple[int, int, Path]]:
    """The arm's finished parts from agent 0 on, in order, up to the first gap."""
    parts = []
    for folder in (arm / "parts").glob("*-*"):
        if folder.is_dir() and (folder / "run_info.json").is_file():
            a, b = (int(x) for x in folder.name.split("-"))
            parts.append((a, b, folder))
    parts.sort()
    out, end = [], 0
    for a, b, folder in parts:
        if a != end:
            break
        out.append((a, b, folder))
        end = b
    return out


def merge(arm: Path) -> int:
    """Stack ``arm``'s parts; the number of agents it then holds."""
    parts = finished_parts(arm)
    if not parts:
        return 0
    for name in ARRAYS:
        if all((folder / name).is_file() for _, _, folder in parts):
            np.save(arm / name, np.concatenate([np.load(folder / name) for _, _, folder in parts]))
    records = []
    for a, b, folder in parts:
        info = json.loads((folder / "run_info.json").read_text())
        config = json.loads((folder / "config.json").read_text())
        records.append({"agents": [a, b], "seed": config["seed"], "runs": config["runs"],
                        "wall_time_s": info.get("wall_time_s"),
                        "agent_steps": info.get("agent_steps"), "commit": info.get("commit")})
    first = json.loads((parts[0][2] / "config.json").read_text())
    first.update(runs=parts[-1][1], seed=records[0]["seed"])
    (arm / "config.json").write_text(json.dumps(first, indent=1) + "\n")
    (arm / "parts.json").write_text(json.dumps(records, indent=1) + "\n")
    return parts[-1][1]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    args = parser.parse_args(argv)
    for arm in sorted(p for p in args.folder.iterdir() if (p / "parts").is_dir()):
        n = merge(arm)
        wall = sum(r["wall_time_s"] or 0 for r in
                   json.loads((arm / "parts.json").read_text())) if n else 0
        print(f"{arm.name}: {n} agents ({wall:,.0f} s of parts)")


if __name__ == "__main__":
    main()
