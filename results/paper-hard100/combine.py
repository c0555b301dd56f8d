"""Figure 6 and the hard instance's claims at the paper's 100 runs (issue 30).

``results/paper-v3/hard`` (then ``results/paper/hard``) ran 60 agents per kind (seeds
1000-1059). That study was removed from the tree: it is ``results/paper-v3`` in git at 6835785,
restorable with ``git archive 6835785 results/paper-v3 | tar -x``. A second study ran the next 40
(``skillchain reproduce paper --instances hard --hard-runs 40 --seed 1060``). By the seed
contract agent ``p`` of a population started at seed ``S`` is the single agent with seed
``S + p`` (``skillchain verify``), so the two studies' rows stacked are exactly the 100-agent
study of seed 1000; this script stacks them (checking that every other setting agrees and the
seeds follow on), writes ``hard/<agent>/`` with the 100-run arrays and ``config.json``
(``runs 100, seed 1000``: what ``skillchain verify`` replays, agents 60-99 included), and the
report with Figure 6.

    python results/paper-hard100/combine.py results/paper-v3 /work/runs/hard-extra  # first, second
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
AGENTS = ("flat", "skill-chaining", "given-options")
STACKED = ("returns.npy", "lengths.npy", "n_options.npy")  # [runs, ...] rows in agent order


def stack(first: Path, second: Path, out: Path) -> dict:
    """``out``: ``first``'s rows then ``second``'s, for every array both hold; the config of
    the whole population. Raises ``SystemExit`` naming what disagrees."""
    a = json.loads((first / "config.json").read_text())
    b = json.loads((second / "config.json").read_text())
    if b["seed"] != a["seed"] + a["runs"]:
        sys.exit(f"{second}/config.json: seed {b['seed']} does not follow on from {first}'s "
                 f"{a['seed']} + {a['runs']} runs")
    import dataclasses

    from skillchain_torch.trainers.config.config import TrainConfig

    # Fields added since the first study read as what it ran with (LEGACY_FIELDS); the given
    # options are each study's own file.
    ca, cb = (TrainConfig.load_json(d / "config.json") for d in (first, second))
    differ = cb.mismatches(dataclasses.replace(ca, runs=cb.runs, seed=cb.seed,
                                               options=cb.options))
    if differ:
        sys.exit(f"{first} and {second} differ in {', '.join(differ)}")
    out.mkdir(parents=True, exist_ok=True)
    for name in STACKED:
        if (first / name).is_file() and (second / name).is_file():
            np.save(out / name, np.concatenate([np.load(first / name), np.load(second / name)]))
    config = {**a, "runs": a["runs"] + b["runs"]}
    (out / "config.json").write_text(json.dumps(config, indent=1) + "\n")
    infos = [json.loads((d / "run_info.json").read_text()) for d in (first, second)]
    info = {"wall_time_s": sum(i["wall_time_s"] for i in infos),
            "agent_steps": sum(i["agent_steps"] for i in infos),
            "commit": infos[1]["commit"],
            "stacked_from": [{"dir": str(d.relative_to(ROOT)) if d.is_relative_to(ROOT) else
                              str(d), "runs": c["runs"], "seed": c["seed"], **i}
                             for d, c, i in zip((first, second), (a, b), infos)]}
    (out / "run_info.json").write_text(json.dumps(info, indent=1) + "\n")
    return config


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("first", type=Path, help="the study that ran the first 60 agents "
                        "(its hard/<agent> folders)")
    parser.add_argument("second", type=Path, help="the study that ran the agents after the "
                        "first 60 (its hard/<agent> folders)")
    args = parser.parse_args(argv)
    from skillchain_torch.trainers.study.paper_report import write_report

    for agent in AGENTS:
        stack(args.first.resolve() / "hard" / agent, args.second / "hard" / agent,
              HERE / "hard" / agent)
    write_report(HERE, names=[f"hard/{a}" for a in AGENTS], quiet=True)
    # Figures 7 and 8 need a skill-chaining checkpoint; the first study has them at 60 runs.
    for stale in ("fig7.png", "fig8.png"):
        if (HERE / stale).is_file():
            (HERE / stale).unlink()
    print(f"wrote {HERE / 'README.md'}")


if __name__ == "__main__":
    main()
