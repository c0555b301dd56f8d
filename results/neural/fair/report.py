"""Issue 53's fair comparison: neural skill chaining against neural flat, per 25-episode window,
with 95% intervals over runs, and where neural flat plateaus by the issue's rule.

    python results/neural/fair/report.py            # every ENV folder here with both arms
    python results/neural/fair/report.py Acrobot-v1

For each ``ENV/`` whose ``flat-neural`` and ``sc-neural`` (``bash results/neural/fair.sh ENV``)
have ``returns.npy``, writes ``ENV/tables.md`` and ``ENV/curves.png``:

* each arm's mean return per 25-episode window (95% Student-t interval over runs), the
  windows in which neural flat's mean lies inside the previous window's interval marked ``=``
  (the plateau rule: neural flat plateaus at the first such window);
* skill chaining minus flat per window (Welch's 95% interval), and over the plateau window,
  the windows after it, and the last 25 episodes;
* options held at the end and how executions ended (per agent-episode, last 25 episodes).

Example:
    >>> rows = windows(300, 25)
    >>> rows[0], rows[-1]
    ((1, 25), (276, 300))
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.compare import save_comparison
from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci

HERE = Path(__file__).resolve().parent
ARMS = ("flat-neural", "sc-neural")
WIDTH = 25


def windows(episodes: int, width: int = WIDTH) -> list[tuple[int, int]]:
    """1-based inclusive ``(first, last)`` episode windows of ``width`` covering ``episodes``."""
    return [(a, a + width - 1) for a in range(1, episodes - width + 2, width)]


def window_means(returns: np.ndarray, spans: list[tuple[int, int]]) -> list[np.ndarray]:
    """Per run, the mean return over each window: ``[runs]`` arrays, one per span."""
    return [returns[:, a - 1:b].mean(1) for a, b in spans]


def plateau(returns: np.ndarray, spans: list[tuple[int, int]]) -> list[bool]:
    """Per window, whether its mean lies inside the previous window's 95% t interval (the
    issue's plateau rule; the first window never does)."""
    means = window_means(returns, spans)
    inside = [False]
    for before, now in zip(means, means[1:]):
        m, h = mean_ci(before)
        inside.append(bool(abs(now.mean() - m) <= h))
    return inside


def fmt(mean: float, half: float, sign: bool = False) -> str:
    return f"{mean:+,.0f} ± {half:,.0f}" if sign else f"{mean:,.0f} ± {half:,.0f}"


def report(env: Path) -> list[str]:
    runs = {arm: {name: np.load(env / arm / f"{name}.npy")
                  for name in ("returns", "n_options", "option_outcomes")}
            for arm in ARMS}  # fmt: skip
    flat, sc = runs["flat-neural"]["returns"], runs["sc-neural"]["returns"]
    episodes = min(flat.shape[1], sc.shape[1])
    spans = windows(episodes)
    flat_plateau = plateau(flat, spans)
    first = next((i for i, hit in enumerate(flat_plateau) if hit), None)
    head = "| arm | runs | " + " | ".join(f"{a}-{b}" for a, b in spans) + " |"
    rule = "|---|---:|" + "---:|" * len(spans)
    lines = [f"# {env.name}: neural skill chaining against neural flat", "",
             "Mean return per 25-episode window, 95% t interval over runs; `=`: the mean lies "
             "inside the previous window's interval (the plateau rule, read on neural flat).", "",
             head, rule]  # fmt: skip
    for arm in ARMS:
        r = runs[arm]["returns"]
        cells = [fmt(*mean_ci(m)) + (" =" if mark else "")
                 for m, mark in zip(window_means(r, spans), plateau(r, spans))]
        lines.append(f"| {arm} | {len(r)} | " + " | ".join(cells) + " |")
    diffs = [diff_ci(s, f) for s, f in zip(window_means(sc, spans), window_means(flat, spans))]
    lines += ["| sc - flat (Welch) | | " + " | ".join(fmt(d, h, True) for d, h in diffs) + " |",
              ""]  # fmt: skip
    if first is None:
        lines.append(f"Neural flat does not plateau by the rule within {episodes} episodes.")
    else:
        a, b = spans[first]
        after = (a, episodes)
        d_after = diff_ci(sc[:, after[0] - 1:].mean(1), flat[:, after[0] - 1:].mean(1))
        lines.append(f"Neural flat plateaus by the rule at episodes {a}-{b} (its mean inside "
                     f"the interval of {spans[first - 1][0]}-{spans[first - 1][1]}). Skill "
                     f"chaining minus flat over {after[0]}-{after[1]}: {fmt(*d_after, True)}.")
    last = (episodes - WIDTH + 1, episodes)
    d_last = diff_ci(sc[:, last[0] - 1:].mean(1), flat[:, last[0] - 1:].mean(1))
    d_all = diff_ci(sc.mean(1), flat.mean(1))
    lines += ["", f"Over the last {WIDTH} episodes: {fmt(*d_last, True)}; over all "
              f"{episodes}: {fmt(*d_all, True)} (sc - flat, Welch 95%).", ""]  # fmt: skip
    n_options = runs["sc-neural"]["n_options"]
    outcomes = runs["sc-neural"]["option_outcomes"][:, last[0] - 1:]  # success, timeout, fail
    per = outcomes.sum(1) / WIDTH  # per agent-episode, per run
    cells = [fmt(*mean_ci(per[:, j])) for j in range(per.shape[1])]
    lines += [f"Skill chaining at episode {episodes}: {fmt(*mean_ci(n_options[:, -1]))} options "
              f"per agent (most {int(n_options[:, -1].max())}); executions per agent-episode "
              f"over {last[0]}-{last[1]}: success {cells[0]}, timeout {cells[1]}, other "
              f"failure {cells[2]}.", ""]  # fmt: skip
    return lines


def returns_of(env: Path, arm: str) -> np.ndarray | None:
    """An arm's ``[runs, episodes]`` returns: its own ``returns.npy``, or, while it runs, the
    first episodes committed in ``interim/`` (a run's first N episodes are the N-episode run)."""
    path = env / arm / "returns.npy"
    if path.is_file():
        return np.load(path)
    interim = sorted((env / "interim").glob(f"{arm}-returns-1-*.npy"))
    return np.load(interim[-1]) if interim else None


def cause_report(env: Path, arm: str) -> list[str]:
    """``arm`` (a run that changes a suspected cause, e.g. ``sc-neural-o50``) against neural flat
    and neural skill chaining over its episodes, per 25-episode window."""
    runs = {name: returns_of(env, name) for name in ("flat-neural", "sc-neural", arm)}
    missing = [name for name, r in runs.items() if r is None]
    if missing:
        return [f"{env.name}/{arm}: no returns yet for {', '.join(missing)}"]
    episodes = min(r.shape[1] for r in runs.values())
    spans = windows(episodes) + [(episodes // 2 + 1, episodes)]
    lines = [f"## {env.name}: {arm} against neural flat and neural skill chaining", "",
             "| | " + " | ".join(f"{a}-{b}" for a, b in spans) + " |",
             "|---|" + "---:|" * len(spans)]  # fmt: skip
    for name, r in runs.items():
        lines.append(f"| {name} ({len(r)} runs) | "
                     + " | ".join(fmt(*mean_ci(m)) for m in window_means(r, spans)) + " |")
    for other in ("flat-neural", "sc-neural"):
        diffs = [diff_ci(x, y) for x, y in zip(window_means(runs[arm], spans),
                                               window_means(runs[other], spans))]
        lines.append(f"| {arm} - {other} | "
                     + " | ".join(fmt(d, h, True) for d, h in diffs) + " |")
    return lines + [""]


def figure(env: Path, path: Path) -> None:
    """Both arms' learning curves (mean and 95% interval over runs), through the library's
    ``skillchain plot`` figure."""
    curves = {arm: np.load(env / arm / "returns.npy") for arm in ARMS}
    save_comparison(curves, path, title=f"{env.name}: neural skill chaining (default) "
                    "against neural flat")  # fmt: skip


def main(names: list[str]) -> int:
    envs = [HERE / n for n in names] if names else sorted(p for p in HERE.iterdir() if p.is_dir())
    done = [e for e in envs if all((e / arm / "returns.npy").is_file() for arm in ARMS)]
    for env in envs:
        if env not in done:
            print(f"{env.name}: not both arms finished (needs {', '.join(ARMS)})")
    for env in done:
        text = "\n".join(report(env))
        (env / "tables.md").write_text(text)
        figure(env, env / "curves.png")
        print(text)
    for env in envs:  # the runs on a suspected cause (fair_cause.sh), against both arms
        for arm in sorted(p.name for p in env.glob("sc-neural-*") if (p / "returns.npy").is_file()):
            text = "\n".join(cause_report(env, arm))
            (env / f"tables-{arm}.md").write_text(text)
            print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
