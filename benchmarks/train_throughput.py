"""Training throughput of the flat Sarsa and skill-chaining agents (environment, decision and
update together).

    python benchmarks/train_throughput.py            # P = 1, 10, 100 and a short population run
    python benchmarks/train_throughput.py --full     # ... and the paper's 100 x 250 run
    python benchmarks/train_throughput.py --threads 2

Rows: ``PopulationTrainer`` with P agents on pinball_simple_single (paper defaults: order-4
Fourier basis, alpha 0.001, gamma 1, epsilon 0.01) timed over a fixed number of agent steps
after a short warm-up; agent steps per second count every agent's environment step with its
decision and Sarsa update. The peer is a plain per-step NumPy loop of the same agent, one agent,
written below as one would write it by hand, around pynball-rl's pure-Python simulator (the
bench extra, ``pip install -e ".[bench]"``; the peer is left out without it); ratios are ours /
peer, measured in the same invocation.

The skill-chaining rows time agents with options live against flat agents of the same
population size and the same kind (compiled kernels, the default, or torch only), in
alternating chunks (``--rounds``), and report the median cost per agent step and its range
over the rounds, and the overall cost (all rounds' time per agent step).

The last line times a whole population run (``--full``: 100 agents x 250 episodes, the paper's
experiment; default: 100 agents x 5 episodes, said so in the output).
"""

from __future__ import annotations

import argparse
import itertools
import math
import statistics
import time
from importlib import resources
from pathlib import Path

import numpy as np
import torch

from skillchain_torch.backends import sarsa as native_sarsa
from skillchain_torch.backends.select import same_bits_kernels
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

MAP = "pinball_simple_single"


def time_trainer(population: int, agent_steps: int, threads: int, repeats: int = 3,
                 native: bool | None = None) -> float:
    """Best of ``repeats`` rates (agent steps / s) over ``agent_steps`` after a warm-up
    (``native=False``: torch and Python only, without any compiled piece)."""
    best = 0.0
    for r in range(repeats):
        cfg = TrainConfig(map=MAP, runs=population, episodes=10_000, seed=r)
        with same_bits_kernels(native is not False):
            trainer = PopulationTrainer(cfg, num_threads=threads, native=native)
            trainer.train(max_agent_steps=20 * population)  # warm-up: caches, allocations
            start, done = time.perf_counter(), trainer.agent_steps
            trainer.train(max_agent_steps=done + agent_steps)
        best = max(best, (trainer.agent_steps - done) / (time.perf_counter() - start))
    return best


class NumpySarsa:
    """The peer: one flat Sarsa agent in NumPy, stepping pynball-rl's simulator (the first
    instance's map) one call at a time."""

    def __init__(self, order=4, alpha=0.001, gamma=1.0, epsilon=0.01, seed=0):
        from pynball_rl import PynBall  # the bench extra

        self.c = np.array(list(itertools.product(range(order + 1), repeat=4)), dtype=float)
        self.w = np.zeros((5, self.c.shape[0]))
        self.alpha, self.gamma, self.epsilon = alpha, gamma, epsilon
        self.rng = np.random.default_rng(seed)
        self.env = PynBall(resources.files("pynball_rl") / "configs" / "easy_config.toml")

    def features(self, s):
        x, y, vx, vy = s
        return np.cos(math.pi * (self.c @ np.array([x, y, (vx + 1) / 2, (vy + 1) / 2])))

    def act(self, q):
        if self.rng.random() < self.epsilon:
            return int(self.rng.integers(5))
        best = np.flatnonzero(q == q.max())
        return int(best[self.rng.integers(best.size)])

    def run(self, steps: int) -> float:
        s = self.env.reset()
        phi = self.features(s)
        a = self.act(self.w @ phi)
        begin = time.perf_counter()
        for _ in range(steps):
            s, reward, terminated, _ = self.env.step(a)
            if terminated:
                delta = reward - self.w[a] @ phi
                self.w[a] += self.alpha * delta * phi
                s = self.env.reset()
                phi = self.features(s)
                a = self.act(self.w @ phi)
                continue
            phi1 = self.features(s)
            q1 = self.w @ phi1
            a1 = self.act(q1)
            delta = reward + self.gamma * q1[a1] - self.w[a] @ phi
            self.w[a] += self.alpha * delta * phi
            phi, a = phi1, a1
        return steps / (time.perf_counter() - begin)


OPTIONS = Path(__file__).parent / "data" / "skill_chaining_options.pt"


def skill_chaining_trainer(population: int, threads: int, seed: int = 0,
                           native: bool | None = None) -> PopulationTrainer:  # fmt: skip
    """Skill-chaining agents with options live, warmed up.

    Every agent starts with the options one agent discovered in a real run
    (``benchmarks/data/skill_chaining_options.pt``: agent 2 of the seed-0 run of
    ``trainers/README.md``, the one with the most options: 9 of its 12 slots, 3 goal options, a
    chain of depth 3, 2 learned) and discovery stays on, so the timed steps pay for everything
    options cost: classifier and target evaluations, option policies, intra-option updates,
    examples, a 100-sweep refit after every execution, and new options. The top level starts
    at zero, so options are tried often: a heavy case. ``native=False``: torch and Python only.
    """
    from skillchain_torch.options import OptionBank

    cfg = TrainConfig(agent="skill-chaining", map=MAP, runs=population, episodes=10_000,
                      seed=seed, slots=12)  # fmt: skip
    # (pieces take their kernels when built: build them inside the switch's block)
    with same_bits_kernels(native is not False):
        trainer = PopulationTrainer(cfg, num_threads=threads, native=native)
        seeds = torch.arange(population, dtype=torch.int64) + seed
        given = OptionBank.from_agent(OPTIONS, 0, population, seeds=seeds)
        trainer.agent.bank.load_state_dict(given.state_dict())
        trainer.train(max_agent_steps=20 * population)
    return trainer


def paired_cost(population: int, threads: int, rounds: int, flat_steps: int,
                options_steps: int) -> dict[str, list[float]]:  # fmt: skip
    """Rates of each round: flat and skill-chaining agents, each with torch kernels only
    (``*_torch``) and with the compiled ones (``*_native``, the default).

    The four trainers run in alternating chunks, ``rounds`` times, so each round gives one
    cost = (skill-chaining time per agent step) / (flat time per agent step) for each kind.
    This machine's speed drifts by tens of percent over minutes; timing them seconds apart
    keeps that drift out of the ratio, which best-of rates taken a minute apart do not.
    """
    trainers = {}
    for name, native in (("flat_torch", False), ("flat_native", None)):
        cfg = TrainConfig(map=MAP, runs=population, episodes=10_000, seed=0)
        with same_bits_kernels(native is not False):  # (built inside: pieces keep kernels)
            trainers[name] = PopulationTrainer(cfg, num_threads=threads, native=native)
            trainers[name].train(max_agent_steps=20 * population)
    for name, native in (("sc_torch", False), ("sc_native", None)):
        trainers[name] = skill_chaining_trainer(population, threads, native=native)
    rates = {name: [] for name in trainers}
    for _ in range(rounds):
        for name, trainer in trainers.items():
            steps = options_steps if name.startswith("sc_") else flat_steps
            with same_bits_kernels(not name.endswith("_torch")):
                start, done = time.perf_counter(), trainer.agent_steps
                trainer.train(max_agent_steps=done + steps)
            rates[name].append((trainer.agent_steps - done) / (time.perf_counter() - start))
    return rates


def time_population_run(runs: int, episodes: int, threads: int) -> tuple[float, int]:
    cfg = TrainConfig(map=MAP, runs=runs, episodes=episodes, seed=0, checkpoint_every=0)
    trainer = PopulationTrainer(cfg, num_threads=threads)
    start = time.perf_counter()
    trainer.train()
    return time.perf_counter() - start, trainer.agent_steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--full", action="store_true", help="time the 100 x 250 run")
    parser.add_argument("--steps", type=int, default=20_000, help="agent steps per row")
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads")
    parser.add_argument("--rounds", type=int, default=15,
                        help="alternating flat / skill-chaining chunks per cost row")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    try:
        peer = max(NumpySarsa(seed=r).run(args.steps // 2) for r in range(2))
    except ModuleNotFoundError:  # pynball-rl (the bench extra) is not installed: no peer
        peer = math.nan
    print(f"flat Sarsa on {MAP}, torch {torch.__version__}, {args.threads} thread(s); "
          f"{args.steps:,} agent steps per row (best of 3)")
    print("compiled: the default (every compiled piece: Pinball step, Fourier arguments, random "
          f"draws, the agents' kernels; built: {native_sarsa.AVAILABLE}); torch only: none")
    print(f"{'P':>5} | {'compiled':>10} | {'torch only':>10} | {'numpy peer':>10} | "
          f"{'ratio':>6} | {'vs torch':>8}")
    print(f"{'-' * 5}-|-{'-' * 10}-|-{'-' * 10}-|-{'-' * 10}-|-{'-' * 6}-|-{'-' * 8}")
    for population in (1, 10, 100):
        rate = time_trainer(population, args.steps, args.threads)
        torch_rate = time_trainer(population, args.steps, args.threads, native=False)
        print(f"{population:>5} | {rate:>10,.0f} | {torch_rate:>10,.0f} | {peer:>10,.0f} | "
              f"{rate / peer:>6.2f} | {rate / torch_rate:>8.2f}")
    print("\nskill chaining with options live (12 slots), alternating with flat agents in the "
          "same process; cost = time per agent step relative to flat agents of the same kind "
          "(target <= 2.5 at P = 100): median over rounds (range), and overall (all rounds' "
          "time per step)")
    print(f"{'P':>5} | {'kind':>10} | {'flat':>10} | {'skill ch.':>9} | {'cost':>18} | "
          f"{'overall':>7}")
    print(f"{'-' * 5}-|-{'-' * 10}-|-{'-' * 10}-|-{'-' * 9}-|-{'-' * 18}-|-{'-' * 7}")
    for population in (1, 100):
        # Chunks of a few hundred steps: shorter ones swing with the bursts of refits and
        # episode ends (a 50-step chunk ranged over 1.3-5.0x).
        flat_steps, options_steps = (3_000, 1_500) if population == 1 else (30_000, 15_000)
        scale = args.steps / 20_000
        rates = paired_cost(population, args.threads, args.rounds,
                            max(1, int(flat_steps * scale)),
                            max(1, int(options_steps * scale)))  # fmt: skip
        for kind, label in (("torch", "torch only"), ("native", "compiled")):
            flat, options = rates[f"flat_{kind}"], rates[f"sc_{kind}"]
            costs = [f / o for f, o in zip(flat, options)]
            cell = f"{statistics.median(costs):.2f} ({min(costs):.2f}-{max(costs):.2f})"
            # every round times the same number of steps of each: mean times per step
            overall = sum(1 / o for o in options) / sum(1 / f for f in flat)
            print(f"{population:>5} | {label:>10} | {statistics.median(flat):>10,.0f} | "
                  f"{statistics.median(options):>9,.0f} | {cell:>18} | {overall:>7.2f}")
    runs, episodes = (100, 250) if args.full else (100, 5)
    wall, steps = time_population_run(runs, episodes, args.threads)
    note = "" if args.full else " (short version; --full times the paper's 100 x 250)"
    print(f"\n{runs} x {episodes} run: {wall:,.1f} s wall, {steps:,} agent steps, "
          f"{steps / wall:,.0f} agent steps/s; the numpy peer would take "
          f"{steps / peer:,.0f} s running the runs one after another{note}")


if __name__ == "__main__":
    main()
