"""The screen's table: mean return per window, 95% Student-t interval over the 10 runs."""

from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.intervals import mean_ci

HERE = Path(__file__).resolve().parent
RUNS = [  # name, target copy every (updates), Adam lr, update every (steps), bootstrap, gamma
    ("acro_flat_dec", 250, 1e-3, 4, "sarsa", 1.0),
    ("acro_flat_tu100", 100, 1e-3, 4, "sarsa", 1.0),
    ("acro_flat_tu25", 25, 1e-3, 4, "sarsa", 1.0),
    ("acro_flat_tu10", 10, 1e-3, 4, "sarsa", 1.0),
    ("acro_flat_tu25te1", 25, 1e-3, 1, "sarsa", 1.0),
    ("acro_flat_tu25max", 25, 1e-3, 4, "max", 1.0),
    ("acro_flat_g99", 25, 1e-3, 4, "max", 0.99),
    ("acro_flat_lr3", 25, 3e-4, 4, "max", 1.0),
    ("acro_flat_lr3s", 25, 3e-4, 4, "sarsa", 1.0),
    ("acro_flat_lr1", 25, 1e-4, 4, "max", 1.0),
]
WINDOWS = [(0, 10), (10, 25), (25, 50), (50, 60)]


def cell(r: np.ndarray, a: int, b: int) -> str:
    mean, half = mean_ci(r[:, a:b].mean(1))
    return f"{mean:,.0f} ± {half:,.0f}"


def main() -> None:
    print("| target copy (updates) | Adam lr | update every | bootstrap | gamma | "
          + " | ".join(f"{a + 1}-{b}" for a, b in WINDOWS) + " |")
    print("|" + "---|" * (5 + len(WINDOWS)))
    for name, tu, lr, te, boot, gamma in RUNS:
        r = np.load(HERE / f"{name}.npy")
        cells = " | ".join(cell(r, a, b) for a, b in WINDOWS)
        print(f"| {tu} | {lr:g} | {te} | {boot} | {gamma:g} | {cells} |")


if __name__ == "__main__":
    main()
