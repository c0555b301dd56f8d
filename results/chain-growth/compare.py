"""Confirm a chain-growth setting on the confirmation seeds against the paper study's runs.

The setting's skill-chaining agents ran as runs of 50 agents (``--seed 1000`` and ``--seed
1050``; by the seed contract they are agents 0-99 of one population with seed 1000). They are
compared, episode window by window, with the first episodes of the paper study's flat and
gestation-10 skill-chaining runs on the same seeds (``results/paper-v2/simple``): an agent's
first 50 episodes do not depend on how many episodes it runs in all. That study was removed from
the tree: it is ``results/paper-v2`` in git at 6835785, restorable with
``git archive 6835785 results/paper-v2 | tar -x``.

    python results/chain-growth/compare.py --name g2 --paper results/paper-v2 \
        runs/confirm/g2-s1000 runs/confirm/g2-s1050
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci

HERE = Path(__file__).resolve().parent
WINDOWS = ((1, 10), (11, 25), (26, 50))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--name", required=True, help="the setting, e.g. g2 (--gestation 2)")
    p.add_argument("--paper", required=True, type=Path, help="the study with the flat and "
                   "gestation-10 skill-chaining runs (its simple/<agent> folders)")
    p.add_argument("runs", nargs="+", type=Path, help="run directories, in seed order")
    args = p.parse_args()
    out = HERE / args.name
    out.mkdir(exist_ok=True)
    arrays = {}
    for name in ("returns", "lengths", "n_options"):
        arrays[name] = np.concatenate([np.load(d / f"{name}.npy") for d in args.runs])
        np.save(out / f"{name}.npy", arrays[name])
    for i, d in enumerate(args.runs):
        shutil.copy(d / "config.json", out / f"config_{i}.json")
        shutil.copy(d / "run_info.json", out / f"run_info_{i}.json")
    R = arrays["returns"]
    E = R.shape[1]
    peers = {k: np.load(args.paper / "simple" / k / "returns.npy")[: len(R), :E]
             for k in ("flat", "skill-chaining")}  # fmt: skip
    rows = [f"| episodes | flat | gestation 10 ({args.paper}) | " + args.name
            + " | " + args.name + " - flat | " + args.name + " - gestation 10 |",
            "|---|---|---|---|---|---|"]  # fmt: skip
    result = {}
    for a, b in WINDOWS:
        w = R[:, a - 1:b].mean(1)
        f, s = (peers[k][:, a - 1:b].mean(1) for k in ("flat", "skill-chaining"))
        cells = [mean_ci(x) for x in (f, s, w)] + [diff_ci(w, f), diff_ci(w, s)]
        result[f"{a}-{b}"] = [list(map(float, c)) for c in cells]
        text = [f"{m:,.0f} ± {h:,.0f}" for m, h in cells[:3]]
        text += [f"{m:+,.0f} ± {h:,.0f}" + (" *" if abs(m) > h else "") for m, h in cells[3:]]
        rows.append(f"| {a}-{b} | " + " | ".join(text) + " |")
    n = arrays["n_options"]
    rows.append("")
    rows.append("Options per agent (mean) at episodes 10 / 25 / 50: "
                + " / ".join(f"{n[:, e - 1].mean():.1f}" for e in (10, 25, 50) if e <= E))
    walls = [json.loads((d / "run_info.json").read_text())["wall_time_s"] for d in args.runs]
    rows.append(f"Longest episode: {int(arrays['lengths'].max()):,} steps; agent steps "
                f"{int(arrays['lengths'].sum()):,}; wall time "
                + " + ".join(f"{w:,.0f} s" for w in walls))  # fmt: skip
    (out / "table.md").write_text("\n".join(rows) + "\n")
    (out / "table.json").write_text(json.dumps(result, indent=1) + "\n")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
