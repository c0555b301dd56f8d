"""How ``hard/skill-chaining`` was made (eighteenth session): the three 48-slot runs of
``results/option-learning/confirm-hard`` (seeds 1000-1049 as two blocks, 1050-1074, 1075-1099)
laid out as this study's four blocks and merged by the library's ``merge_blocks``.

By the seed contract agents ``[a, b)`` of a run are the population run of ``b - a`` agents seeded
``seed + a``, so the blocks are this study's arm; each source's config is checked against the
block's (``mismatches``), files are hard-linked (the checkpoints too: Figures 7 and 8 replay
agents from them), and ``run_info.json`` records the runs' own commits. It writes into an empty
``hard/skill-chaining``; the options banks and checkpoints it needs are not committed. (The
session ran this as a one-off script, tidied here; it set the same files and fields.)

    python results/paper/stack_k48.py
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
SRC = ROOT / "results/option-learning/confirm-hard"
SOURCES = {(0, 25): "end-outside-k48-seeds1000-1049/blocks/0-25",
           (25, 50): "end-outside-k48-seeds1000-1049/blocks/25-50",
           (50, 75): "end-outside-k48-seeds1050-1074",
           (75, 100): "end-outside-k48-seeds1075-1099"}
FILES = ("returns.npy", "lengths.npy", "n_options.npy", "option_outcomes.npy",
         "option_tree.json", "options.pt")
RUNS = ("end-outside-k48-seeds1000-1049", "end-outside-k48-seeds1050-1074",
        "end-outside-k48-seeds1075-1099")


def main() -> None:
    from skillchain_torch.trainers.config.config import TrainConfig
    from skillchain_torch.trainers.distributed.block_merge import merge_blocks
    from skillchain_torch.trainers.distributed.blocks import ShardedRun, block_config
    from skillchain_torch.trainers.study.reproduce import paper_experiments

    [exp] = [e for e in paper_experiments(instances=("hard",)) if e.agent == "skill-chaining"]
    out = HERE / exp.name
    out.mkdir(parents=True)  # (refuses an existing arm)
    exp.config.save_json(out / "config.json")
    run = ShardedRun(exp.config, out, list(SOURCES))
    run.save(workers=2)
    records = {}
    for span, name in SOURCES.items():
        src, dst = SRC / name, run.block_dir(span)
        dst.mkdir(parents=True)
        want = block_config(exp.config, *span, dst)
        have = TrainConfig.load_json(src / "config.json")
        if have.mismatches(want) or (have.runs, have.seed) != (want.runs, want.seed):
            sys.exit(f"{src}/config.json is not agents {span} of this study's arm")
        for f in FILES:
            os.link(src / f, dst / f)
        shutil.copytree(src / "checkpoints", dst / "checkpoints", copy_function=os.link)
        want.save_json(dst / "config.json")
        if (src / "block.json").is_file():
            record = json.loads((src / "block.json").read_text())
        else:  # a one-process run: its run_info holds the same numbers
            info = json.loads((src / "run_info.json").read_text())
            record = {"agents": want.runs, "seed": want.seed, "agent_steps": info["agent_steps"],
                      "wall_time_s": info["wall_time_s"],
                      "compiled_agent": info.get("compiled_agent", True)}
        (dst / "block.json").write_text(json.dumps(record, indent=1) + "\n")
        records[span] = record
    infos = [json.loads((SRC / r / "run_info.json").read_text()) for r in RUNS]
    info = merge_blocks(run, records, workers=2, wall=sum(i["wall_time_s"] for i in infos),
                        commit=infos[0]["commit"])
    info["stacked_from"] = [f"results/option-learning/confirm-hard/{r}" for r in RUNS]
    info["commits"] = {"seeds 1000-1049": infos[0]["commit"], "seeds 1050-1099": infos[1]["commit"]}
    info["wall_time_note"] = ("the three runs' wall times added (seeds 1000-1049 in two blocks on "
                              "two cores; the others one core each, in other sessions)")
    (out / "run_info.json").write_text(json.dumps(info, indent=2) + "\n")


if __name__ == "__main__":
    main()
