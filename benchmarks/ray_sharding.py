"""Wall time of one run in one process against the same run sharded over Ray workers.

    python benchmarks/ray_sharding.py                    # the issue's sizes (long)
    python benchmarks/ray_sharding.py --sc 4x30 --flat 20x100
    python benchmarks/ray_sharding.py --sweep            # also: a 4-cell sweep, run twice

Rows, each a whole ``skillchain train`` command timed end to end (start-up, Ray's start-up,
training, merge), for (a) skill chaining (default 10 runs x 100 episodes, seed 100) and (b)
the flat agent (default 100 x 250, seed 0), on pinball_simple_single:

* ``1 process``: today's path;
* ``2 workers static``: the agents cut into 2 contiguous shards (``--block-size ceil(P/2)``,
  the default);
* ``2 workers dynamic, shrinking blocks`` (``--block-size shrink``): blocks handed to the
  worker that frees up, each a ``2N``-th of the agents left (large first, single agents last);
* ``2 workers dynamic, blocks of 1``: every agent its own block (``--block-size 1``).

``driver s`` is the run's own ``run_info.json`` wall time (for sharded runs from the first
block submitted to the merge written), ``command s`` adds process and Ray start-up. Every
sharded run is checked against the one-process arrays bit for bit. The load averages
(``uptime``) beside each row say how busy the machine was.

``--sweep``: ``skillchain sweep`` of 4 flat cells (alpha x order, 10 runs x 100 episodes),
then the same command again, which must skip every cell; prints both times and the summary.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SKILLCHAIN = [sys.executable, "-m", "skillchain_torch.trainers.config.cli"]


def load() -> str:
    """The 1, 5 and 15 minute load averages."""
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def timed(argv: list[str]) -> float:
    """Seconds of ``skillchain ARGV`` (it must succeed)."""
    clock = time.perf_counter()
    subprocess.run([*SKILLCHAIN, *argv], check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - clock


def compare(name: str, agent: str, runs: int, episodes: int, seed: int, workers: int,
            root: Path, skip_ones: bool = False) -> list[dict]:  # fmt: skip
    """The rows of one run (see the module docstring), each printed as it is measured
    (``skip_ones``: leave out blocks of 1)."""
    base = ["train", "--agent", agent, "--map", "pinball_simple_single", "--runs", str(runs),
            "--episodes", str(episodes), "--seed", str(seed), "--quiet"]
    modes = [("1 process", []),
             (f"{workers} workers static",
              ["--workers", str(workers), "--block-size", str(math.ceil(runs / workers))]),
             (f"{workers} workers dynamic, shrinking blocks",
              ["--workers", str(workers), "--block-size", "shrink"]),
             (f"{workers} workers dynamic, blocks of 1",
              ["--workers", str(workers), "--block-size", "1"])][:3 if skip_ones else 4]
    rows, reference = [], None
    for mode, extra in modes:
        out = root / f"{name}-{mode.replace(' ', '-')}"
        before = load()
        command = timed([*base, "--out", str(out), *extra])
        info = json.loads((out / "run_info.json").read_text())
        returns, lengths = np.load(out / "returns.npy"), np.load(out / "lengths.npy")
        if reference is None:
            reference = (returns, lengths)
        same = (np.array_equal(returns, reference[0], equal_nan=True)
                and np.array_equal(lengths, reference[1]))
        rows.append({"run": name, "mode": mode, "blocks": info.get("blocks", 1),
                     "driver": info["wall_time_s"], "command": command, "same": same,
                     "steps": info["agent_steps"], "load": f"{before} -> {load()}"})
        print(table(rows[-1:]).splitlines()[-1], flush=True)  # a killed run keeps its rows
    return rows


def table(rows: list[dict]) -> str:
    lines = ["| run | mode | blocks | driver s | command s | vs 1 process (driver / command) "
             "| arrays | load before -> after |", "|---|---|---:|---:|---:|---:|---|---|"]
    first = {}
    for r in rows:
        one = first.setdefault(r["run"], r)
        lines.append(f"| {r['run']} | {r['mode']} | {r['blocks']} | {r['driver']:.1f} | "
                     f"{r['command']:.1f} | {r['driver'] / one['driver']:.2f}x / "
                     f"{r['command'] / one['command']:.2f}x | "
                     f"{'identical' if r['same'] else 'DIFFER'} | {r['load']} |")
    return "\n".join(lines)


def sweep(root: Path, workers: int, runs: int, episodes: int) -> str:
    spec = root / "sweep.toml"
    spec.write_text(f"[base]\nagent = \"flat\"\nruns = {runs}\nepisodes = {episodes}\n"
                    f"seed = 0\n[grid]\nalpha = [0.001, 0.002]\norder = [3, 4]\n")
    argv = ["sweep", str(spec), "--out", str(root / "sweep"), "--workers", str(workers),
            "--quiet"]
    before = load()
    first = timed(argv)
    middle = load()
    again = timed(argv)
    summary = (root / "sweep" / "summary.md").read_text().split("\n\n")[2]
    return (f"sweep of 4 flat cells x {runs} runs x {episodes} episodes on {workers} workers: "
            f"{first:.1f} s (load {before}); re-run {again:.1f} s, every cell skipped "
            f"(load {middle})\n\n{summary}")


def size(text: str) -> tuple[int, int]:
    runs, episodes = text.lower().split("x")
    return int(runs), int(episodes)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sc", type=size, default=(10, 100), metavar="RUNSxEPISODES",
                        help="skill-chaining run (default 10x100, seed 100)")
    parser.add_argument("--flat", type=size, default=(100, 250), metavar="RUNSxEPISODES",
                        help="flat run (default 100x250, seed 0)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--only", choices=("sc", "flat"), default=None)
    parser.add_argument("--sweep", action="store_true", help="also the 4-cell sweep")
    parser.add_argument("--skip-blocks-of-1", action="store_true",
                        help="leave out the blocks-of-1 rows (the slowest)")
    parser.add_argument("--sweep-size", type=size, default=(10, 100), metavar="RUNSxEPISODES")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        if args.only in (None, "sc"):
            rows += compare(f"skill-chaining {args.sc[0]}x{args.sc[1]}", "skill-chaining",
                            *args.sc, 100, args.workers, root, args.skip_blocks_of_1)
        if args.only in (None, "flat"):
            rows += compare(f"flat {args.flat[0]}x{args.flat[1]}", "flat", *args.flat, 0,
                            args.workers, root, args.skip_blocks_of_1)
        print(table(rows), flush=True)
        if args.sweep:
            print()
            print(sweep(root, args.workers, *args.sweep_size))


if __name__ == "__main__":
    main()
