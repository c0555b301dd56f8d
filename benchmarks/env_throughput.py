"""Environment steps per second of PinballEnv beside pynball-rl 1.0.2, in one invocation.

Both simulators play the same uniform random actions (resetting an environment when it reaches
the goal). pynball-rl is a single-environment pure-Python simulator, so its rate does not depend
on the batch size; ours steps ``B`` independent environments per call.

    python benchmarks/env_throughput.py                 # the table of the README
    python benchmarks/env_throughput.py --torchrl       # also time TorchRL's env.step(td)

Columns: ``ours`` is ``PinballEnv.step_raw`` plus ``reset_raw`` of finished environments (what
the trainers call), through the compiled step when it is built; ``no C`` is the same without
it (the tensor path; the same bits); ``torchrl`` is
``EnvBase.step`` with TensorDicts; ratios are against pynball-rl's rate measured in the same
run.
"""

from __future__ import annotations

import argparse
import time
from importlib import resources

import torch

from skillchain_torch.envs.pinball import PinballEnv, physics

PYNBALL_CONFIGS = {
    "pinball_simple_single": "easy_config.toml",
    "pinball_hard_single": "hard_config.toml",
}


def random_actions(steps: int, batch: int, seed: int = 0) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return torch.randint(0, 5, (steps, batch), generator=gen)


def time_ours(map_name: str, batch: int, steps: int, warmup: int = 50) -> float:
    env = PinballEnv(map_name, batch_size=[batch], seed=0)
    env.reset_raw()
    actions = random_actions(steps + warmup, batch)
    for t in range(steps + warmup):
        if t == warmup:
            start = time.perf_counter()
        _, _, terminated, _ = env.step_raw(actions[t])
        if bool(terminated.any()):
            env.reset_raw(terminated)
    return batch * steps / (time.perf_counter() - start)


def time_torchrl(map_name: str, batch: int, steps: int) -> float:
    env = PinballEnv(map_name, batch_size=[batch], seed=0)
    td = env.reset()
    actions = random_actions(steps, batch)
    start = time.perf_counter()
    for t in range(steps):
        td["action"] = actions[t]
        td = env.step_and_maybe_reset(td)[1]
    return batch * steps / (time.perf_counter() - start)


def time_pynball(map_name: str, steps: int) -> float:
    from pynball_rl import PynBall  # the bench extra: pip install -e ".[bench]"

    path = resources.files("pynball_rl") / "configs" / PYNBALL_CONFIGS[map_name]
    env = PynBall(path)
    env.reset()
    actions = random_actions(steps, 1)[:, 0].tolist()
    start = time.perf_counter()
    for a in actions:
        _, _, terminal, _ = env.step(a)
        if terminal:
            env.reset()
    return steps / (time.perf_counter() - start)


def steps_for(batch: int, budget: int) -> int:
    return max(20, budget // batch)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawTextHelpFormatter
    )
    parser.add_argument("--maps", nargs="+", default=list(PYNBALL_CONFIGS))
    parser.add_argument("--batches", nargs="+", type=int, default=[1, 64, 1024, 4096])
    parser.add_argument("--budget", type=int, default=200_000, help="env steps per measurement")
    parser.add_argument("--torchrl", action="store_true", help="also time EnvBase.step(td)")
    args = parser.parse_args()
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, float64, CPU")

    header = "| map | B | ours (steps/s) | no C (steps/s) | pynball-rl (steps/s) | ratio |"
    sep = "|---|---:|---:|---:|---:|---:|"
    if args.torchrl:
        header += " torchrl step (steps/s) |"
        sep += "---:|"
    print("\n" + header + "\n" + sep)
    for map_name in args.maps:
        peer = time_pynball(map_name, 20_000)
        for batch in args.batches:
            steps = steps_for(batch, args.budget if batch > 1 else 20_000)
            ours = time_ours(map_name, batch, steps)
            native, physics.NATIVE = physics.NATIVE, False
            plain = time_ours(map_name, batch, steps)
            physics.NATIVE = native
            row = (f"| {map_name} | {batch} | {ours:,.0f} | {plain:,.0f} | {peer:,.0f} | "
                   f"{ours / peer:.1f}x |")
            if args.torchrl:
                row += f" {time_torchrl(map_name, batch, steps_for(batch, 20_000)):,.0f} |"
            print(row, flush=True)


if __name__ == "__main__":
    main()
