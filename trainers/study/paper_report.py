"""The report of ``skillchain reproduce paper``: tables with 95% intervals and the claims checked.

Statistics are over runs: each run's mean return over an episode window, then the mean over
runs with a 95% Student t interval (mean +- t(n - 1) sd / sqrt(n)). A difference between two
agent kinds is the difference of their window means with Welch's 95% t interval
(:mod:`.intervals`); "consistency" is the sd over runs of the window mean, compared as a ratio
with a bootstrap 95% interval (2,000 resamples of the runs, a fixed seed).

Example:
    >>> import numpy as np
    >>> a, b = np.array([[1.0, 3.0], [3.0, 5.0]]), np.array([[0.0, 0.0], [2.0, 2.0]])
    >>> window(a, 1, 2).tolist()
    [2.0, 4.0]
    >>> _fmt_diff(*diff_ci(window(a, 1, 2), window(b, 1, 2)))
    '+2 ± 6'
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci

__all__ = ["window", "sd_ratio_ci", "check_claims", "write_report", "WINDOWS"]

WINDOWS = ((1, 10), (11, 25), (26, 50), (51, 100), (101, 150), (151, 200), (201, 250))


def window(returns, first: int, last: int) -> np.ndarray:
    """Each run's mean over episodes ``first..last`` (1-based, inclusive): ``[runs]``."""
    r = np.asarray(returns, dtype=np.float64)
    return r[:, first - 1 : min(last, r.shape[1])].mean(axis=1)


def sd_ratio_ci(x, y, resamples: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """``(sd(x) / sd(y), low, high)``: bootstrap 95% interval of the ratio of sds over runs."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    rng = np.random.default_rng(seed)
    ratios = np.empty(resamples)
    for i in range(resamples):
        xs, ys = rng.choice(x, x.size), rng.choice(y, y.size)
        ratios[i] = xs.std(ddof=1) / max(ys.std(ddof=1), 1e-300)
    low, high = np.percentile(ratios, [2.5, 97.5])
    return float(x.std(ddof=1) / y.std(ddof=1)), float(low), float(high)


def _fmt(mean: float, half: float) -> str:
    return f"{mean:,.0f} ± {half:,.0f}"


def _fmt_diff(d: float, half: float) -> str:
    mark = " *" if abs(d) > half else ""
    return f"{d:+,.0f} ± {half:,.0f}{mark}"


def _load(run_dir: Path) -> dict:
    out = {"returns": np.load(run_dir / "returns.npy"), "lengths": np.load(run_dir / "lengths.npy"),
           "config": json.loads((run_dir / "config.json").read_text())}  # fmt: skip
    info = run_dir / "run_info.json"
    out["info"] = json.loads(info.read_text()) if info.is_file() else {}
    if (run_dir / "n_options.npy").is_file():
        out["n_options"] = np.load(run_dir / "n_options.npy")
    return out


def check_claims(instance: str, runs: dict) -> list[dict]:
    """The paper's claims for ``instance`` (``"simple"`` or ``"hard"``) from the loaded runs
    (``runs[agent]``: ``returns [n, E]``); each ``{claim, measure, value, holds}``."""
    flat, sc = runs["flat"]["returns"], runs["skill-chaining"]["returns"]
    given = runs.get("given-options", {}).get("returns")
    E = min(flat.shape[1], sc.shape[1])
    late = (max(1, E - 49), E)
    claims = []

    def diff(a, b, w, claim, want):
        if w[0] > w[1]:  # a run too short for this claim's window
            claims.append({"claim": claim, "measure": f"episodes {w[0]}-", "value": "not run",
                           "holds": False})  # fmt: skip
            return
        d, half = diff_ci(window(a, *w), window(b, *w))
        holds = (d - half > 0) if want == "better" else (d + half < 0) if want == "worse" \
            else (abs(d) <= half)
        claims.append({"claim": claim, "measure": f"episodes {w[0]}-{w[1]}",
                       "value": _fmt_diff(d, half), "holds": bool(holds)})  # fmt: skip

    if instance == "simple":
        diff(sc, flat, (26, min(50, E)), "skill chaining significantly better than flat by "
             "episode 50 (skill chaining - flat)", "better")
    else:
        diff(sc, flat, (1, min(10, E)), "a slight, transient early penalty for skill chaining "
             "(skill chaining - flat)", "worse")
        diff(sc, flat, (max(1, E - 49), E), "then far better than flat (skill chaining - flat)",
             "better")
    ratio, low, high = sd_ratio_ci(window(sc, *late), window(flat, *late))
    claims.append({"claim": "skill chaining more consistent than flat at the end (sd over runs, "
                   "skill chaining / flat)", "measure": f"episodes {late[0]}-{late[1]}",
                   "value": f"{ratio:.2f} [{low:.2f}, {high:.2f}]", "holds": bool(high < 1)})
    if given is not None:
        G = given.shape[1]
        diff(given, flat, (1, min(10, G)), "given options start far better than flat agents "
             "(given - flat)", "better")
        d, half = diff_ci(window(given, 1, min(10, G)), window(flat, max(1, E - 49), E))
        claims.append({"claim": "given options' first episodes beat the flat agents' final "
                       "level (given 1-10 - flat last 50)", "measure": "episodes 1-10 vs "
                       f"{max(1, E - 49)}-{E}", "value": _fmt_diff(d, half),
                       "holds": bool(d - half > 0)})  # fmt: skip
        w = (max(1, min(G, E) - 49), min(G, E))
        d, half = diff_ci(window(given, *w), window(sc, *w))
        claims.append({"claim": "given options reach the level of the agents that discovered "
                       "them (given - skill chaining)", "measure": f"episodes {w[0]}-{w[1]}",
                       "value": _fmt_diff(d, half), "holds": bool(d + half >= 0)})  # fmt: skip
    return claims


def _table(runs: dict, windows) -> list[str]:
    agents = [a for a in ("flat", "skill-chaining", "given-options") if a in runs]
    head = "| episodes | " + " | ".join(agents)
    cols = []
    if "skill-chaining" in runs:
        cols.append(("skill-chaining", "flat"))
    if "given-options" in runs:
        cols += [("given-options", "flat"), ("given-options", "skill-chaining")]
    head += "".join(f" | {a} - {b}" for a, b in cols) + " |"
    lines = [head, "|" + "---|" * (1 + len(agents) + len(cols))]
    E = min(runs[a]["returns"].shape[1] for a in agents)
    for first, last in windows:
        if first > E:
            break
        w = (first, min(last, E))
        row = [f"{w[0]}-{w[1]}"]
        row += [_fmt(*mean_ci(window(runs[a]["returns"], *w))) for a in agents]
        row += [_fmt_diff(*diff_ci(window(runs[a]["returns"], *w),
                                   window(runs[b]["returns"], *w))) for a, b in cols]
        lines.append("| " + " | ".join(row) + " |")
    return lines


def _consistency(runs: dict, windows) -> list[str]:
    agents = [a for a in ("flat", "skill-chaining", "given-options") if a in runs]
    lines = ["| episodes | " + " | ".join(f"{a}: sd / >= 9,000 / length" for a in agents) + " |",
             "|" + "---|" * (1 + len(agents))]  # fmt: skip
    E = min(runs[a]["returns"].shape[1] for a in agents)
    for first, last in windows:
        if first > E:
            break
        w = (first, min(last, E))
        cells = []
        for a in agents:
            r, L = runs[a]["returns"][:, w[0] - 1 : w[1]], runs[a]["lengths"][:, w[0] - 1 : w[1]]
            cells.append(f"{r.mean(1).std(ddof=1):,.0f} / {np.mean(r >= 9000):.2f} / "
                         f"{L.mean():,.0f}")
        lines.append(f"| {w[0]}-{w[1]} | " + " | ".join(cells) + " |")
    return lines


def _runs_table(runs: dict) -> list[str]:
    lines = ["| run | runs x episodes | agent steps | steps per run (min-max) | longest episode | "
             "wall time | commit |", "|---|---|---|---|---|---|---|"]  # fmt: skip
    for a, run in runs.items():
        L, info = run["lengths"], run["info"]
        steps = L.sum(1)
        lines.append(f"| {a} | {L.shape[0]} x {L.shape[1]} | {int(steps.sum()):,} | "
                     f"{int(steps.min()):,}-{int(steps.max()):,} | {int(L.max()):,} | "
                     f"{info.get('wall_time_s', float('nan')):,.0f} s | "
                     f"{str(info.get('commit'))[:12]} |")
    return lines


def _runaways(runs: dict, threshold: int = 10_000) -> list[str]:
    """Episodes longer than ``threshold`` after an agent has reached the goal 50 times."""
    lines = []
    for a, run in runs.items():
        L = run["lengths"]
        late = L[:, 50:]
        hits = np.argwhere(late > threshold)
        lines.append(f"- {a}: {len(hits)} episodes of more than {threshold:,} steps after "
                     f"episode 50" + (f" (agents {sorted(set(int(p) for p, _ in hits))}, the "
                                      f"longest {int(late.max()):,} steps)" if len(hits) else ""))
    return lines


def write_report(out: str | Path, names: list[str] | None = None, quiet: bool = False,
                 figures: bool = True) -> Path:  # fmt: skip
    """Write ``out/README.md``, ``out/report.json`` and the figures from the run directories
    ``out/<instance>/<agent>``; returns the README's path."""
    out = Path(out)
    names = names or [f"{i}/{a}" for i in ("simple", "hard")
                      for a in ("flat", "skill-chaining", "given-options")]  # fmt: skip
    by_instance: dict[str, dict] = {}
    for name in names:
        if (out / name / "returns.npy").is_file():
            instance, agent = name.split("/")
            by_instance.setdefault(instance, {})[agent] = _load(out / name)
    md = ["# Skill chaining on Pinball: the paper's experiments", "",
          "Written by `skillchain reproduce paper` (`skillchain_torch.trainers.study.reproduce`). "
          "Mean return over runs of each run's window mean ± a 95% Student t interval; "
          "differences with Welch's 95% t interval (`*`: the interval excludes 0).",
          ""]  # fmt: skip
    report = {}
    for instance, runs in by_instance.items():
        if "flat" not in runs:
            continue
        cfg = runs["flat"]["config"]
        md += [f"## {instance}: `{cfg['map']}`", ""]
        md += _table(runs, WINDOWS) + [""]
        md += ["Consistency: sd over runs of the window mean / share of episodes with return >= "
               "9,000 / mean episode length.", ""] + _consistency(runs, WINDOWS) + [""]
        if "skill-chaining" in runs:
            claims = check_claims(instance, runs)
            report[instance] = claims
            md += ["The paper's claims:", "", "| claim | measure | value | holds |",
                   "|---|---|---|---|"]  # fmt: skip
            md += [f"| {c['claim']} | {c['measure']} | {c['value']} | "
                   f"{'yes' if c['holds'] else 'no'} |" for c in claims] + [""]
            n_opt = runs["skill-chaining"].get("n_options")
            if n_opt is not None:
                md += [f"Options per skill-chaining agent at the end: {n_opt[:, -1].mean():.1f} "
                       f"(min {n_opt[:, -1].min()}, max {n_opt[:, -1].max()}).", ""]
        md += ["Runs:", ""] + _runs_table(runs) + [""]
        md += ["Runaway episodes:", ""] + _runaways(runs) + [""]
        if figures:
            md += _figures(out, instance, runs, quiet)
    discussion = out / "DISCUSSION.md"  # hand-written: what differs from the paper, and why
    if discussion.is_file():
        md += [discussion.read_text().rstrip(), ""]
    (out / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    path = out / "README.md"
    path.write_text("\n".join(md) + "\n")
    return path


def _figures(out: Path, instance: str, runs: dict, quiet: bool) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from skillchain_torch.trainers.study.paper_figures import (
        good_solutions,
        initiation_figure,
        plot_curves,
        solution_figure,  # fmt: skip
        trained_agents,
    )

    curve, sol, sets = ("fig4a", "fig4b", "fig5") if instance == "simple" else \
        ("fig6", "fig7", "fig8")
    cfg = runs["flat"]["config"]
    ax = plot_curves({a: r["returns"] for a, r in runs.items()},
                     title=f"{cfg['map']}: mean return with 95% intervals", smooth=1)
    ax.figure.tight_layout()
    ax.figure.savefig(out / f"{curve}.png", dpi=120)
    plt.close(ax.figure)
    lines = [f"![learning curves]({curve}.png)", ""]
    sc_dir = out / instance / "skill-chaining"
    try:
        trainer, first = trained_agents(sc_dir)
    except (ValueError, FileNotFoundError) as err:
        kept = [name for name in (sol, sets) if (out / f"{name}.png").is_file()]
        if len(kept) == 2:  # a fresh clone: the figures are committed, the checkpoints are not
            return lines + [f"![greedy solutions]({sol}.png)", "",
                            f"![initiation sets]({sets}.png)", "",
                            f"({sol} and {sets} as drawn when the run finished: its "
                            "checkpoints are not here to redraw them.)", ""]  # fmt: skip
        return lines + [f"(Figures {sol} and {sets} need the skill-chaining run's checkpoint: "
                        f"{err})", ""]
    agent = trainer.agent
    held = agent.bank.live().sum(-1).numpy()
    order = sorted(range(agent.population), key=lambda p: -held[p])[:16]
    solutions = good_solutions(agent, cfg["map"], agents=order)
    solution_figure(solutions, cfg["map"], out / f"{sol}.png", first_agent=first,
                    title="greedy solutions coloured by option (primitive actions black)")
    lines += [f"![greedy solutions]({sol}.png)", ""]
    try:
        initiation_figure(agent, solutions, cfg["map"], out / f"{sets}.png", first_agent=first,
                          title="initiation sets and sample trajectories of the options used")
        lines += [f"![initiation sets]({sets}.png)", ""]
    except ValueError as err:
        lines += [f"({sets}: {err})", ""]
    return lines
