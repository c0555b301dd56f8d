"""The hard given-options arm at 48 slots, re-made in slices of agents that each finish in one
session: the study's own command cannot, because its options banks are not committed.

Why: the arm needs the 100 discoverers' option banks (``hard/skill-chaining/options.pt``,
~130 MB, not committed). The nineteenth session made the arm, but its work never landed (its CI
machine ran out of disk), and the next session started on a fresh machine without the banks.
A 12-13 agent slice costs ~250-360 core-seconds per agent, discoverers and given agents together
(its slowest agent sets its wall time): about 9 core-hours for the arm, more than a session on 2
cores. So each slice ``[a, b)`` of agents is made end to end:

1. its discoverers: the study's skill-chaining arm for agents ``[a, b)`` (by the seed contract,
   ``runs = b - a``, ``seed = 1000 + a``), checked bit for bit against the committed arm's rows
   (returns, lengths, options held);
2. its given-options agents: the study's given-options arm for the same agents, agent p taking
   discoverer p's options (``--options-agent each``), checked bit for bit against the lost
   run's first 75 episodes (``results/option-learning/given-hard/k48-study-partial``);
3. the raw arrays, config and run info into ``hard/given-slices/<a>-<b>/`` (committed).

Each step resumes from its checkpoints (``runs/k48-given/``) within a session. When the slices
cover all 100 agents, ``stack`` writes them as the study's ``hard/given-options`` arm, and
``skillchain reproduce paper --out results/paper --report-only`` rewrites the report.

    python results/paper/given_hard_slices.py run 57 78 &    # one core each: ~22 agents
    python results/paper/given_hard_slices.py run 78 100 &   # a slice finishes in ~2 h
    python results/paper/given_hard_slices.py status
    python results/paper/given_hard_slices.py stack
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
WORK = ROOT / "runs" / "k48-given"
SLICES = HERE / "hard" / "given-slices"
ARM = HERE / "hard" / "given-options"
DISCOVERERS = HERE / "hard" / "skill-chaining"
PARTIAL = ROOT / "results/option-learning/given-hard/k48-study-partial"  # its episodes 1-75
ARRAYS = ("returns.npy", "lengths.npy")  # what a given-options run writes


def _experiments():
    from skillchain_torch.trainers.study.reproduce import paper_experiments

    return {e.agent: e for e in paper_experiments(instances=("hard",))}


def _train(config, run_dir: Path) -> float:
    """Train (or resume, or skip if done) ``config`` in ``run_dir``; its wall time so far."""
    from skillchain_torch.trainers.config.config import TrainConfig
    from skillchain_torch.trainers.study.reproduce import train_dir

    run_dir.mkdir(parents=True, exist_ok=True)
    if (run_dir / "config.json").is_file():
        if TrainConfig.load_json(run_dir / "config.json").mismatches(config):
            sys.exit(f"{run_dir}/config.json differs from this slice's; remove it")
    else:
        config.save_json(run_dir / "config.json")
    code = train_dir(run_dir, quiet=False)
    if code != 0:
        sys.exit(f"{run_dir}: skillchain train exited {code}")
    return json.loads((run_dir / "run_info.json").read_text())["wall_time_s"]


def _same(made: Path, study: Path, a: int, b: int, why: str) -> None:
    """Exit unless ``made`` equals rows ``[a, b)`` of ``study`` over the episodes both hold."""
    x, y = np.load(made), np.load(study)[a:b]
    n = min(x.shape[1], y.shape[1])
    if not np.array_equal(x[:, :n], y[:, :n]):
        sys.exit(f"{made} differs from {study} rows {a}-{b} over episodes 1-{n}: {why}")


def _shown(path: Path) -> Path:
    """``path`` relative to the repository where it lies inside it."""
    return path.relative_to(ROOT) if path.is_relative_to(ROOT) else path


def _copy_config(src: Path, dst: Path) -> None:
    """``src`` with its options bank named relative to the repository: the absolute path of
    the machine that made it means nothing on another (the bank itself is not committed)."""
    config = json.loads(src.read_text())
    config["options"] = str(_shown(Path(config["options"])))
    dst.write_text(json.dumps(config, indent=2) + "\n")


def run_slice(a: int, b: int) -> Path:
    """Make slice ``[a, b)`` end to end; returns its committed folder."""
    exps = _experiments()
    sc_cfg, given_cfg = exps["skill-chaining"].config, exps["given-options"].config
    seed = sc_cfg.seed + a
    sc_dir, given_dir = WORK / f"sc-{a}-{b}", WORK / f"given-{a}-{b}"
    sc_wall = _train(dataclasses.replace(sc_cfg, runs=b - a, seed=seed), sc_dir)
    for name in ("returns.npy", "lengths.npy", "n_options.npy"):
        _same(sc_dir / name, DISCOVERERS / name, a, b, "the discoverers are not the study's, "
              "so their options would not be either")
    given = dataclasses.replace(given_cfg, runs=b - a, seed=seed,
                                options=str(sc_dir / "options.pt"), options_agent=None)
    given_wall = _train(given, given_dir)
    for name in ("returns.npy", "lengths.npy"):  # the lost run's first 75 episodes, committed
        _same(given_dir / name, PARTIAL / name, a, b, "the given agents are not the lost run's")
    out = SLICES / f"{a}-{b}"
    out.mkdir(parents=True, exist_ok=True)
    for name in ARRAYS:
        shutil.copyfile(given_dir / name, out / name)
    _copy_config(given_dir / "config.json", out / "config.json")
    info = json.loads((given_dir / "run_info.json").read_text())
    info["discoverers_wall_time_s"] = sc_wall
    info["discoverers_match_the_study"] = True
    (out / "run_info.json").write_text(json.dumps(info, indent=2) + "\n")
    print(f"slice {a}-{b}: discoverers {sc_wall:,.0f} s (match the study), given options "
          f"{given_wall:,.0f} s -> {_shown(out)}")
    return out


def _slices() -> list[tuple[int, int]]:
    """The finished slices' ``(a, b)``, in agent order."""
    spans = [tuple(int(x) for x in d.name.split("-")) for d in SLICES.glob("*-*")
             if (d / "run_info.json").is_file()]
    return sorted(spans)


def status() -> None:
    spans = _slices()
    done = sum(b - a for a, b in spans)
    print(f"{done} of 100 agents in {len(spans)} slices: {spans}")


def stack() -> None:
    """The finished slices as the study's ``hard/given-options`` arm (refused unless they
    cover agents 0-99 exactly once)."""
    spans = _slices()
    if [a for a, _ in spans] != [0] + [b for _, b in spans[:-1]] or spans[-1][1] != 100:
        sys.exit(f"the slices {spans} do not cover agents 0-99 exactly once")
    exp = _experiments()["given-options"]
    dirs = [SLICES / f"{a}-{b}" for a, b in spans]
    if ARM.exists():
        shutil.rmtree(ARM)  # (the lost run's sharding.json would make reproduce resume it)
    ARM.mkdir(parents=True)
    for name in ARRAYS:
        np.save(ARM / name, np.concatenate([np.load(d / name) for d in dirs]))
    exp.config.save_json(ARM / "config.json")
    infos = [json.loads((d / "run_info.json").read_text()) for d in dirs]
    info = {"wall_time_s": sum(i["wall_time_s"] for i in infos),
            "agent_steps": sum(i["agent_steps"] for i in infos),
            "discoverers_wall_time_s": sum(i["discoverers_wall_time_s"] for i in infos),
            "slices": [f"{a}-{b}" for a, b in spans],
            "commits": sorted({i["commit"] for i in infos}),
            "stacked": time.strftime("%Y-%m-%d"),
            "wall_time_note": "the slices' one-core wall times added (given options only; "
                              "discoverers_wall_time_s: re-making their options)"}
    info["agent_steps_per_second"] = info["agent_steps"] / info["wall_time_s"]
    (ARM / "run_info.json").write_text(json.dumps(info, indent=2) + "\n")
    print(f"{_shown(ARM)}: {len(spans)} slices stacked")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="make slice [A, B) end to end")
    run.add_argument("a", type=int)
    run.add_argument("b", type=int)
    sub.add_parser("status", help="which agents are done")
    sub.add_parser("stack", help="write the finished slices as hard/given-options")
    args = parser.parse_args(argv)
    if args.command == "run":
        if not 0 <= args.a < args.b <= 100:
            parser.error(f"slice {args.a}-{args.b}: expected 0 <= A < B <= 100")
        run_slice(args.a, args.b)
    elif args.command == "status":
        status()
    else:
        stack()


if __name__ == "__main__":
    main()
