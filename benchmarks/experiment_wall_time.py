"""Whole experiments, as a researcher waits for them: wall time of skill chaining against flat.

    python benchmarks/experiment_wall_time.py                # 10 x 100, seed 100 (issue 15)
    python benchmarks/experiment_wall_time.py --runs 4 --episodes 20
    python benchmarks/experiment_wall_time.py --paper results/paper   # Figure 4a's three runs

The first form trains the flat agent and the skill-chaining agent (the default reading) on
``pinball_simple_single`` with the same seeds, one after the other in this process, and prints
their wall times, agent steps and ratios (target: skill chaining at most 4x flat's wall time).
It also reports the tail: the time spent after 90% of the agents had finished, when a few
agents step alone at the P = 1 price.

``--paper DIR`` reads the ``run_info.json`` of a finished ``skillchain reproduce paper`` study
and prints Figure 4a's three runs (target: at most 15 minutes in all on a 2-core machine).
A study run with ``--instances simple`` records its whole wall time in ``DIR/timing.json``
(its blocks are the jobs, two processes at a time); that is Figure 4a's wall time. For older
studies, whose runs were whole processes two at a time, it is estimated as the critical path
max(flat, skill chaining) + given options.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from skillchain_torch.trainers import PopulationTrainer, TrainConfig


def timed_run(config: TrainConfig) -> dict:
    """Train ``config`` in this process; wall time, agent steps and the tail's share."""
    trainer = PopulationTrainer(config)
    marks = []  # (wall time, agents still running) after each batch of episode ends

    def post_episodes(trainer, batch):
        marks.append((time.perf_counter(), trainer.num_active))

    trainer.register_op("post_episodes", post_episodes)
    start = time.perf_counter()
    trainer.train()
    wall = time.perf_counter() - start
    tail_start = next((t for t, active in marks if active <= max(1, config.runs // 10)), None)
    tail = 0.0 if tail_start is None else time.perf_counter() - tail_start
    steps = trainer.lengths.sum(1)
    return {"wall_s": wall, "agent_steps": int(steps.sum()), "max_steps": int(steps.max()),
            "min_steps": int(steps.min()), "tail_s": min(tail, wall),
            "longest_episode": int(trainer.lengths.max())}  # fmt: skip


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--repeat", type=int, default=1,
                        help="train both agents this many times, alternating (flat, skill "
                             "chaining, flat, ...), and also print each pair's ratio and the "
                             "median: the VM's speed drifts by tens of percent within minutes")
    parser.add_argument("--paper", type=Path, default=None,
                        help="a finished reproduce study: print Figure 4a's wall times")
    args = parser.parse_args(argv)
    if args.paper is not None:
        rows = {}
        for agent in ("flat", "skill-chaining", "given-options"):
            info = json.loads((args.paper / "simple" / agent / "run_info.json").read_text())
            rows[agent] = info
            print(f"| {agent} | {info['agent_steps']:,} | {info['wall_time_s']:,.0f} s |")
        timing = args.paper / "timing.json"
        if timing.is_file():  # the study's own clock (blocks as jobs)
            record = json.loads(timing.read_text())
            runs = sorted({r for i in record["invocations"] for r in i["runs"]})
            if all(r.startswith("simple/") for r in runs):
                minutes = record["seconds"] / 60
                print(f"Figure 4a: {minutes:.1f} min of wall time, measured "
                      f"({len(record['invocations'])} invocation(s); target 15 min: "
                      f"{'met' if minutes <= 15 else 'not met'})")
                return
        path = max(rows["flat"]["wall_time_s"], rows["skill-chaining"]["wall_time_s"]) + \
            rows["given-options"]["wall_time_s"]
        total = sum(r["wall_time_s"] for r in rows.values())
        print(f"Figure 4a: {total / 60:.1f} min of process time; {path / 60:.1f} min of wall time "
              f"with two processes, estimated (target 15 min)")
        return
    pairs = []
    for _ in range(max(1, args.repeat)):
        results = {}
        for agent in ("flat", "skill-chaining"):
            cfg = TrainConfig(agent=agent, runs=args.runs, episodes=args.episodes,
                              seed=args.seed, checkpoint_every=0)  # fmt: skip
            results[agent] = timed_run(cfg)
        pairs.append(results)
    if len(pairs) > 1:
        ratios = [r["skill-chaining"]["wall_s"] / r["flat"]["wall_s"] for r in pairs]
        print("| pair | flat | skill chaining | ratio |\n|---|---:|---:|---:|")
        for i, (r, ratio) in enumerate(zip(pairs, ratios)):
            flat_s, sc_s = r["flat"]["wall_s"], r["skill-chaining"]["wall_s"]
            print(f"| {i + 1} | {flat_s:.1f} s | {sc_s:.1f} s | {ratio:.2f}x |")
        median = sorted(ratios)[len(ratios) // 2]
        print(f"median ratio {median:.2f}x (range {min(ratios):.2f}-{max(ratios):.2f}x) over "
              f"{len(ratios)} pairs; target <= 4x: {'met' if median <= 4 else 'not met'}\n")
        results = sorted(pairs, key=lambda r: r["skill-chaining"]["wall_s"] /
                         r["flat"]["wall_s"])[len(pairs) // 2]  # the median pair in full
    flat = results["flat"]
    print(f"pinball_simple_single, {args.runs} runs x {args.episodes} episodes, seed {args.seed}")
    print("| agent | wall time | agent steps | agent steps/s | steps per run | longest episode "
          "| tail (<= 10% of agents left) | wall time / flat |")
    print("|---|---:|---:|---:|---|---:|---:|---:|")
    for agent, r in results.items():
        print(f"| {agent} | {r['wall_s']:.1f} s | {r['agent_steps']:,} | "
              f"{r['agent_steps'] / r['wall_s']:,.0f} | {r['min_steps']:,}-{r['max_steps']:,} | "
              f"{r['longest_episode']:,} | {r['tail_s']:.1f} s | "
              f"{r['wall_s'] / flat['wall_s']:.2f}x |")
    sc = results["skill-chaining"]
    per_step = (sc["wall_s"] / sc["agent_steps"]) / (flat["wall_s"] / flat["agent_steps"])
    print(f"per agent step: skill chaining costs {per_step:.2f}x flat; target for the whole run: "
          f"<= 4x flat's wall time ({'met' if sc['wall_s'] <= 4 * flat['wall_s'] else 'not met'})")


if __name__ == "__main__":
    main()
