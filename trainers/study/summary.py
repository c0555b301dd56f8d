"""Tables of a finished run: mean return +- standard error across runs per episode window.

For each window the statistic is computed per run (its mean return over the window's
episodes), then averaged over runs, with the standard error ``sd / sqrt(runs)`` (sample sd).
``skillchain summarize DIR`` prints it from ``DIR/returns.npy`` and ``DIR/lengths.npy``.

Example:
    >>> import numpy as np
    >>> r = np.array([[0.0, 10.0], [2.0, 30.0]])
    >>> mean, se = window_stats(r, 1, 2)
    >>> mean, round(se, 6)
    (10.5, 5.5)
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

__all__ = ["WINDOWS", "window_stats", "summarize", "format_summary", "summarize_dir"]

# The episode windows of the reference table (1-based, inclusive).
WINDOWS = ((1, 10), (11, 25), (26, 50), (51, 100), (101, 150), (151, 200), (201, 250))


def window_stats(values, first: int, last: int) -> tuple[float, float]:
    """``(mean, standard error)`` over runs of each run's mean over episodes first..last."""
    per_run = np.asarray(values, dtype=np.float64)[:, first - 1 : last].mean(axis=1)
    se = per_run.std(ddof=1) / math.sqrt(per_run.size) if per_run.size > 1 else float("nan")
    return float(per_run.mean()), float(se)


def summarize(returns, lengths, windows=WINDOWS) -> dict:
    """Window statistics of returns and lengths, and the steps per run."""
    returns, lengths = np.asarray(returns), np.asarray(lengths)
    episodes = returns.shape[1]
    rows = []
    for first, last in windows:
        if first > episodes:
            break
        last = min(last, episodes)
        mean, se = window_stats(returns, first, last)
        length, length_se = window_stats(lengths, first, last)
        rows.append({"episodes": f"{first}-{last}", "return_mean": mean, "return_se": se,
                     "length_mean": length, "length_se": length_se})
    steps = lengths.sum(axis=1)
    return {
        "runs": int(returns.shape[0]),
        "episodes": int(episodes),
        "windows": rows,
        "steps_per_run": {"mean": float(steps.mean()), "min": int(steps.min()),
                          "max": int(steps.max())},
        "total_agent_steps": int(steps.sum()),
    }


def format_summary(summary: dict, wall_time: float | None = None) -> str:
    """A Markdown table of :func:`summarize`'s result."""
    lines = [
        f"runs: {summary['runs']}, episodes: {summary['episodes']}",
        "",
        "| episodes | return (mean +- s.e.) | length (mean +- s.e.) |",
        "|---|---|---|",
    ]
    for row in summary["windows"]:
        lines.append(
            f"| {row['episodes']} | {row['return_mean']:,.0f} +- {row['return_se']:,.0f} | "
            f"{row['length_mean']:,.0f} +- {row['length_se']:,.0f} |"
        )
    s = summary["steps_per_run"]
    lines += ["", f"steps per run: mean {s['mean']:,.0f}, min {s['min']:,}, max {s['max']:,}",
              f"total agent steps: {summary['total_agent_steps']:,}"]
    if wall_time is not None:
        rate = summary["total_agent_steps"] / wall_time if wall_time > 0 else float("nan")
        lines.append(f"wall time: {wall_time:,.1f} s ({rate:,.0f} agent steps/s)")
    return "\n".join(lines)


def summarize_dir(out_dir: str | Path) -> str:
    """The formatted summary of a run directory (wall time from ``run_info.json`` if any)."""
    out = Path(out_dir)
    for name in ("returns.npy", "lengths.npy"):
        if not (out / name).is_file():
            raise ValueError(f"{out}: not a finished run directory (no {name})")
    returns = _load_runs_array(out / "returns.npy", "float64")
    lengths = _load_runs_array(out / "lengths.npy", "int64")
    if lengths.shape != returns.shape:
        raise ValueError(f"{out / 'lengths.npy'}: shape {lengths.shape} does not match "
                         f"returns.npy's {returns.shape} (expected [runs, episodes] in both)")
    if np.isnan(returns).any():
        raise ValueError(f"{out}/returns.npy: the run is not finished (NaN returns)")
    if not np.isfinite(returns).all():
        raise ValueError(f"{out / 'returns.npy'}: holds infinite returns")
    if (lengths < 0).any():
        raise ValueError(f"{out / 'lengths.npy'}: holds negative episode lengths")
    wall = None
    info = out / "run_info.json"
    if info.is_file():
        try:
            data = json.loads(info.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise ValueError(f"{info}: not readable JSON ({err})") from None
        wall = data.get("wall_time_s") if isinstance(data, dict) else None
        if wall is not None and (isinstance(wall, bool) or not isinstance(wall, (int, float))):
            raise ValueError(f"{info}: wall_time_s must be a number, got {wall!r}")
    return format_summary(summarize(returns, lengths), wall)


def _load_runs_array(path: Path, kind: str) -> np.ndarray:
    """``path`` as a 2-d ``[runs, episodes]`` numeric array (``kind``: its expected dtype, for
    the message); ``ValueError`` naming the file and the expected shape otherwise."""
    expected = f"a {kind} .npy array of shape [runs, episodes] with runs, episodes >= 1"
    try:
        array = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as err:
        reason = " ".join(str(err).split()).split(". ")[0][:120]
        raise ValueError(f"{path}: not a readable .npy array ({reason}); expected {expected}") \
            from None
    if not isinstance(array, np.ndarray) or array.dtype.kind not in "iuf":
        raise ValueError(f"{path}: holds {getattr(array, 'dtype', type(array).__name__)} "
                         f"values; expected {expected}")
    if array.ndim != 2 or 0 in array.shape:
        raise ValueError(f"{path}: shape {tuple(array.shape)}; expected {expected}")
    return array
