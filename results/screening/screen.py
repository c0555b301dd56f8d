"""The factorial screen of issue 15: skill-chaining readings against flat agents.

Each cell is a ``skillchain train`` run (the screening seed block: seed 0, agents 0..runs-1),
run two at a time (both cores), resumable (a finished cell is skipped, a partial one resumed
from its checkpoint), each killed after ``--cell-timeout`` seconds (then reported as
unfinished; rerun the script to resume it). Then every cell's per-run window means are
compared with the flat cell's, and the table goes to ``results/screening/<instance>/README.md``
with the raw arrays beside it.

    python results/screening/screen.py --instance simple --runs 20 --episodes 100

The cells: the initiation-set reading (first: ``pos0-everything-clearned``; local:
``pos20-fitted-cstart``, ``pos250-fitted-cstart``), the failure bootstrap (``decision``,
``primitives``) and whether stores keep negatives (``kn0``, ``kn1``); optional suffixes
``-top`` (a joining option's policy starts as the agent's own, ``--policy-start top-level``)
``-agN`` (``Q(s, o)`` starts as the agent's state value plus N, ``--value-start agent``),
``-oaX`` (``--option-alpha X``), ``-CX`` (``--completion-reward X``), ``-gN`` (``--gestation
N``), ``-ctX`` (``--convergence-threshold X``), ``-ipo`` (``--intra-option-primitives on``) and
``-int`` (``--option-interruption on``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci

ROOT = Path(__file__).resolve().parents[2]
MAPS = {"simple": "pinball_simple_single", "hard": "pinball_hard_two_starts"}
READINGS = {
    "first": ["--gestation-positives", "0", "--initiation-start", "everything",
              "--initiation-constrain", "learned"],
    "pos20": ["--gestation-positives", "20", "--initiation-start", "fitted",
              "--initiation-constrain", "start"],
    "pos250": ["--gestation-positives", "250", "--initiation-start", "fitted",
               "--initiation-constrain", "start"],
    # the first reading, but no fit until a slot holds both classes
    "wait": ["--gestation-positives", "0", "--initiation-start", "everything",
             "--initiation-constrain", "learned", "--wait-for-both-classes"],
    # true everywhere through a positive intercept (centred features): failures carve
    "biased": ["--gestation-positives", "0", "--initiation-start", "biased",
               "--initiation-bias", "4", "--initiation-centered", "--initiation-constrain",
               "learned"],
}
WINDOWS = ((1, 10), (11, 25), (26, 50), (51, 100), (101, 150), (151, 250))


def cells(names: list[str]) -> dict[str, list[str]]:
    """``{"flat": [...], "first-decision-kn0": [...], ...}``: each cell's CLI arguments."""
    out = {}
    for name in names:
        if name == "flat":
            out[name] = ["--agent", "flat"]
            continue
        reading, boot, kn, *starts = name.split("-")
        out[name] = ["--agent", "skill-chaining", *READINGS[reading], "--failure-bootstrap", boot,
                     "--keep-negatives", "on" if kn == "kn1" else "off"]
        for part in starts:  # "top": the policy starts as the agent's; "agN": Q(s, o) = V + N
            if part == "top":
                out[name] += ["--policy-start", "top-level"]
            elif part.startswith("ag"):
                out[name] += ["--value-start", "agent", "--value-bonus", part[2:] or "0"]
            elif part.startswith("oa"):  # e.g. oa0: option step size 0
                out[name] += ["--option-alpha", part[2:]]
            elif part.startswith("C"):  # e.g. C0: completion reward 0
                out[name] += ["--completion-reward", part[1:]]
            elif part.startswith("ct"):  # e.g. ct0.5: convergence threshold 0.5
                out[name] += ["--convergence-threshold", part[2:]]
            elif part == "ipo":  # the top level's primitives also learn inside options
                out[name] += ["--intra-option-primitives", "on"]
            elif part == "int":  # options are interrupted where no longer greedy
                out[name] += ["--option-interruption", "on"]
            elif part.startswith("g") and part[1:].isdigit():  # e.g. g3: gestation 3 episodes
                out[name] += ["--gestation", part[1:]]
            else:
                raise ValueError(f"cell {name!r}: unknown part {part!r} "
                                 f"(top, agN, oaX, CX, gN, ctX, ipo, int)")  # fmt: skip
    return out


def run_cell(name, extra, args, runs_dir: Path) -> str:
    out = runs_dir / name
    if (out / "run_info.json").exists():
        return f"{name}: done before"
    exe = str(ROOT / ".venv" / "bin" / "skillchain")
    if (out / "checkpoints").is_dir() and any((out / "checkpoints").iterdir()):
        cmd = [exe, "train", "--resume", str(out), "--quiet"]
    else:
        cmd = [exe, "train", "--map", MAPS[args.instance], "--runs", str(args.runs),
               "--episodes", str(args.episodes), "--seed", str(args.seed), "--out", str(out),
               "--overwrite", "--quiet", *extra]
    t = time.time()
    log = open(runs_dir / f"{name}.log", "a")
    try:
        rc = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT,
                            timeout=args.cell_timeout).returncode
    except subprocess.TimeoutExpired:
        return f"{name}: stopped after {args.cell_timeout} s (rerun to resume)"
    return f"{name}: rc {rc} in {time.time() - t:.0f} s"


def load_cell(d: Path):
    """``(returns, lengths, note)`` of a cell: the finished arrays, or the episodes every agent
    completed by the last checkpoint of an unfinished run (``note`` says which)."""
    if (d / "run_info.json").exists():
        return np.load(d / "returns.npy"), np.load(d / "lengths.npy"), ""
    checkpoints = sorted((d / "checkpoints").glob("ckpt_*.pt")) if d.is_dir() else []
    if not checkpoints:
        return None
    import torch

    state = torch.load(checkpoints[-1], weights_only=False, map_location="cpu")["trainer"]
    R, L = np.asarray(state["returns"]), np.asarray(state["lengths"])
    n = int((~np.isnan(R)).all(0).sum())
    return R[:, :n], L[:, :n], f"stopped after {n} episodes"


def report(args, names, runs_dir: Path, out_dir: Path) -> str:
    arrays, notes = {}, {}
    for name in names:
        d = runs_dir / name
        cell = load_cell(d)
        if cell is None or cell[0].shape[1] == 0:
            continue
        R, L, notes[name] = cell
        arrays[name] = (R, L)
        dest = out_dir / name
        dest.mkdir(parents=True, exist_ok=True)
        np.save(dest / "returns.npy", R)
        np.save(dest / "lengths.npy", L)
        for f in ("config.json", "n_options.npy", "run_info.json", "option_tree.json"):
            if (d / f).exists():
                shutil.copy(d / f, dest / f)
    E = args.episodes
    wins = [(a, b) for a, b in WINDOWS if b <= E]
    head = "| cell | " + " | ".join(f"{a}-{b}" for a, b in wins) + \
        " | longest episode | wall s |"
    lines = [head, "|" + "---|" * (len(wins) + 3)]
    flat = arrays.get("flat")
    for name in names:
        if name not in arrays:
            lines.append(f"| {name} | (unfinished) |")
            continue
        R, L = arrays[name]
        info_path = runs_dir / name / "run_info.json"
        info = json.loads(info_path.read_text()) if info_path.exists() else {}
        cellv = []
        for a, b in wins:
            if b > R.shape[1]:
                cellv.append("")
                continue
            m, h = mean_ci(R[:, a - 1:b].mean(1))
            s = f"{m:,.0f} ± {h:,.0f}"
            if flat is not None and name != "flat":
                d, dh = diff_ci(R[:, a - 1:b].mean(1), flat[0][:, a - 1:b].mean(1))
                mark = " **" if d - dh > 0 else (" (worse)" if d + dh < 0 else "")
                s += f"<br>{d:+,.0f} ± {dh:,.0f}{mark}"
            cellv.append(s)
        wall = info.get("wall_seconds", info.get("wall_time_s", float("nan")))
        label = f"{name} ({notes[name]})" if notes[name] else name
        wall = "-" if wall != wall else f"{wall:.0f}"  # (nan: unfinished)
        lines.append(f"| {label} | " + " | ".join(cellv) + f" | {int(L.max()):,} | {wall} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--instance", choices=MAPS, default="simple")
    p.add_argument("--runs", type=int, default=20)
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--cells", nargs="+", default=["flat"] + [
        f"{r}-{b}-{k}" for r in READINGS for b in ("decision", "primitives")
        for k in ("kn0", "kn1")])
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--cell-timeout", type=int, default=1800)
    p.add_argument("--runs-dir", default=None)
    p.add_argument("--report-only", action="store_true")
    args = p.parse_args(argv)
    tag = f"{args.instance}_P{args.runs}_E{args.episodes}_seed{args.seed}"
    runs_dir = Path(args.runs_dir or ROOT / "runs" / "screen" / tag)
    runs_dir.mkdir(parents=True, exist_ok=True)
    spec = cells(args.cells)
    if not args.report_only:
        with ThreadPoolExecutor(args.jobs) as pool:
            for line in pool.map(lambda kv: run_cell(kv[0], kv[1], args, runs_dir),
                                 spec.items()):
                print(line, flush=True)
    out_dir = ROOT / "results" / "screening" / tag
    table = report(args, list(spec), runs_dir, out_dir)
    (out_dir / "table.md").write_text(table + "\n")
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
