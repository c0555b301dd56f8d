"""Whole ``skillchain train`` commands as a user waits for them: flat against skill chaining.

    python benchmarks/command_wall_time.py --repeat 5          # 10 x 100, seed 100, 5 pairs
    python benchmarks/command_wall_time.py --runs 2 --episodes 5 --repeat 1
    python benchmarks/command_wall_time.py --repeat 2 --profile /tmp/sc.prof

Each command is a fresh process (start-up, imports, training with its TensorBoard log and option
monitor, the arrays and figures at the end), timed from launch to exit. The two commands
alternate (flat, skill chaining, flat, ...) because this VM's speed drifts by tens of percent
within minutes, so each pair's ratio compares like with like; the table gives every pair and
the median and range. Issue 29's targets: skill chaining's command at most 4x flat's, and
monitoring plus figures at most 10% of a run's wall time, read from the ``seconds`` that each
run writes into ``run_info.json`` (share of the whole command).

``--profile FILE`` also runs the skill-chaining command once under cProfile and prints where
its time went: start-up, the training loop, the option monitor, TensorBoard scalars, the
discovery log, and the outputs written after training (figures included).

Example (a tiny run, a few seconds)::

    python benchmarks/command_wall_time.py --map pinball_box --runs 2 --episodes 2 --repeat 1
"""

from __future__ import annotations

import argparse
import json
import pstats
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def command(agent: str, args, out: Path, prefix=()) -> list[str]:
    exe = shutil.which("skillchain") or str(Path(sys.executable).parent / "skillchain")
    return [*prefix, exe, "train", "--agent", agent, "--map", args.map, "--runs",
            str(args.runs), "--episodes", str(args.episodes), "--seed", str(args.seed),
            "--out", str(out), "--overwrite", "--quiet"]  # fmt: skip


def timed(agent: str, args, out: Path) -> dict:
    """Run one command; its wall time and the ``seconds`` of its ``run_info.json``."""
    start = time.perf_counter()
    subprocess.run(command(agent, args, out), check=True)
    wall = time.perf_counter() - start
    seconds = json.loads((out / "run_info.json").read_text()).get("seconds", {})
    return {"wall": wall, **seconds}


def shares(profile: Path) -> list[tuple[str, float]]:
    """Seconds of the parts of a profiled command (cumulative times of their entry points)."""
    stats = pstats.Stats(str(profile)).stats
    total = max(ct for (_, _, _, ct, _) in stats.values())

    def cum(file: str, *names: str) -> float:
        return sum(ct for (path, _, name), (_, _, _, ct, _) in stats.items()
                   if path.endswith(file) and name in names)  # fmt: skip

    write = cum("run_outputs.py", "train_and_write")
    train = cum("population.py", "train")
    monitor = cum("option_monitor.py", "_count", "post_episodes", "post_train")
    scalars = cum("trainers/logging.py", "post_episodes", "pre_train", "post_train")
    discovery = cum("discovery_log.py", "post_episodes", "post_train")
    loop = train - monitor - scalars - discovery
    return [("whole command", total), ("start-up (imports, config)", total - write),
            ("training loop (without the hooks)", loop), ("option monitor", monitor),
            ("TensorBoard scalars", scalars), ("discovery log", discovery),
            ("outputs after training (arrays, options.pt, figures)", write - train)]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", default="pinball_simple_single")
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--repeat", type=int, default=2, help="alternating pairs (default 2)")
    parser.add_argument("--out", type=Path, default=None,
                        help="where the runs go (default: a temporary directory)")
    parser.add_argument("--profile", type=Path, default=None,
                        help="also profile one skill-chaining command into this file")
    args = parser.parse_args(argv)
    root = args.out or Path(tempfile.mkdtemp(prefix="command_wall_time_"))
    rows = []
    for pair in range(1, args.repeat + 1):
        flat = timed("flat", args, root / "flat")
        sc = timed("skill-chaining", args, root / "skill_chaining")
        rows.append((pair, flat, sc))
        print(f"pair {pair}: flat {flat['wall']:.1f} s, skill chaining {sc['wall']:.1f} s",
              file=sys.stderr, flush=True)
    print(f"`skillchain train` {args.runs} x {args.episodes}, seed {args.seed}, {args.map}; "
          f"monitoring + outputs = option monitor + TensorBoard scalars + discovery log + "
          f"everything written after training (run_info.json `seconds`)\n")
    print("| pair | flat | skill chaining | ratio | sc training | sc monitoring + outputs "
          "| share of the sc command | flat monitoring + outputs |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    ratios, parts = [], []
    for pair, flat, sc in rows:
        ratio, watched = sc["wall"] / flat["wall"], sc.get("monitoring_and_outputs", 0.0)
        ratios.append(ratio)
        parts.append(watched / sc["wall"])
        print(f"| {pair} | {flat['wall']:.1f} s | {sc['wall']:.1f} s | {ratio:.2f}x | "
              f"{sc.get('train', 0.0):.1f} s | {watched:.1f} s | {100 * parts[-1]:.1f}% | "
              f"{flat.get('monitoring_and_outputs', 0.0):.1f} s |")
    print(f"\nratio sc / flat: median {statistics.median(ratios):.2f}x (range "
          f"{min(ratios):.2f}-{max(ratios):.2f}x, target <= 4x); monitoring + outputs: median "
          f"{100 * statistics.median(parts):.1f}% of the skill-chaining command (range "
          f"{100 * min(parts):.1f}-{100 * max(parts):.1f}%, target <= 10%)")
    if args.profile is not None:
        out = root / "skill_chaining_profiled"
        subprocess.run(command("skill-chaining", args, out,
                               (sys.executable, "-m", "cProfile", "-o", str(args.profile))),
                       check=True)  # fmt: skip
        parts = shares(args.profile)
        total = parts[0][1]
        print(f"\nProfile of one skill-chaining command ({args.profile}; under the profiler):\n")
        print("| part | seconds | share |\n|---|---:|---:|")
        for name, seconds in parts:
            print(f"| {name} | {seconds:.1f} | {100 * seconds / total:.1f}% |")


if __name__ == "__main__":
    main()
