"""Agent steps per second of neural skill chaining at P = 1, 10, 100, against a CleanRL-style DQN.

    python benchmarks/neural_speed.py                     # MountainCar-v0, CPU
    python benchmarks/neural_speed.py --device cuda       # where a GPU is lent
    python benchmarks/neural_speed.py --steps 300 --populations 1 10   # a quick look
    python benchmarks/neural_speed.py --steps 300 --populations 100 --floor  # what 10x needs

The peer, run in the same process on the same env: a single-agent DQN loop written as CleanRL's
``dqn.py`` writes it (a Gymnasium env stepped directly, an MLP of the same size as
:class:`~skillchain_torch.modules.MLPQHead` (two tanh layers of 64), a tensor replay buffer,
Adam at 1e-3, a minibatch of 32 every 4 steps, a target copy every 250 updates). The agent is
``skillchain train``'s: ``TrainConfig(agent="skill-chaining", preset="paper", top_head="mlp",
option_head="mlp", initiation="mlp")`` in a :class:`PopulationTrainer` (the env stepped through
TorchRL's ``GymEnv``, discovery, option heads and classifiers included), timed over
``--steps`` population steps after a warm-up. The ratio is (agent steps/s) / (DQN steps/s):
above 1 the population does more agent steps per second than one DQN.

Example (a few seconds)::

    python benchmarks/neural_speed.py --steps 100 --dqn-steps 500 --populations 1 2
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import gymnasium as gym
import torch
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def dqn_steps_per_second(env_id: str, steps: int, device: str, seed: int = 0) -> float:
    """CleanRL-style DQN: one env, one network, replay, epsilon 0.05 after a short decay."""
    env = gym.make(env_id)
    obs, _ = env.reset(seed=seed)
    n_obs, n_act = env.observation_space.shape[0], env.action_space.n
    net = nn.Sequential(nn.Linear(n_obs, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh(),
                        nn.Linear(64, n_act)).to(device)  # fmt: skip
    target = nn.Sequential(*[type(m)(*m.weight.shape[::-1]) if isinstance(m, nn.Linear)
                             else nn.Tanh() for m in net]).to(device)  # fmt: skip
    target.load_state_dict(net.state_dict())
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-3)
    size = 50_000
    buf_obs = torch.zeros(size, n_obs, device=device)
    buf_next = torch.zeros(size, n_obs, device=device)
    buf_act = torch.zeros(size, dtype=torch.int64, device=device)
    buf_rew = torch.zeros(size, device=device)
    buf_done = torch.zeros(size, device=device)
    g = torch.Generator().manual_seed(seed)
    updates, start = 0, time.perf_counter()
    for t in range(steps):
        epsilon = max(0.05, 1.0 - t / 1000)
        if float(torch.rand((), generator=g)) < epsilon:
            action = int(torch.randint(n_act, (), generator=g))
        else:
            with torch.no_grad():
                action = int(net(torch.as_tensor(obs, device=device)).argmax())
        nxt, reward, terminated, truncated, _ = env.step(action)
        i = t % size
        buf_obs[i], buf_next[i] = torch.as_tensor(obs), torch.as_tensor(nxt)
        buf_act[i], buf_rew[i], buf_done[i] = action, float(reward), float(terminated)
        obs = nxt if not (terminated or truncated) else env.reset()[0]
        if t >= 32 and t % 4 == 0:
            idx = torch.randint(min(t + 1, size), (32,), generator=g).to(device)
            with torch.no_grad():
                best = target(buf_next[idx]).max(1).values
                y = buf_rew[idx] + best * (1 - buf_done[idx])
            q = net(buf_obs[idx]).gather(1, buf_act[idx, None])[:, 0]
            loss = nn.functional.smooth_l1_loss(q, y)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            updates += 1
            if updates % 250 == 0:
                target.load_state_dict(net.state_dict())
    return steps / (time.perf_counter() - start)


def agent_steps_per_second(env_id: str, population: int, steps: int, device: str) -> float:
    from skillchain_torch.trainers import PopulationTrainer, TrainConfig

    cfg = TrainConfig(agent="skill-chaining", preset="paper", env=f"gymnasium:{env_id}",
                      runs=population, episodes=10_000, seed=0, device=device,
                      top_head="mlp", option_head="mlp", initiation="mlp")  # fmt: skip
    trainer = PopulationTrainer(cfg)
    trainer.train(max_agent_steps=min(steps, 50) * population)  # warm-up: imports, first fits
    before, start = trainer.agent_steps, time.perf_counter()
    trainer.train(max_agent_steps=before + steps * population)
    return (trainer.agent_steps - before) / (time.perf_counter() - start)


def flat_steps_per_second(population: int, steps: int, env_id: str | None = None) -> float:
    """Linear flat Sarsa (``--agent flat``, Fourier order 4) at P agents: on Gymnasium's
    ``env_id`` (MountainCar steps in one call: ``skillchain_torch.envs.classic``) or, with
    ``None``, on Pinball's first instance."""
    from skillchain_torch.trainers import PopulationTrainer, TrainConfig

    env = None if env_id is None else f"gymnasium:{env_id}"
    trainer = PopulationTrainer(TrainConfig(agent="flat", env=env, runs=population,
                                            episodes=10_000, seed=0))  # fmt: skip
    trainer.train(max_agent_steps=min(steps, 50) * population)
    before, start = trainer.agent_steps, time.perf_counter()
    trainer.train(max_agent_steps=before + steps * population)
    return (trainer.agent_steps - before) / (time.perf_counter() - start)


def live_option_steps_per_second(env_id: str, population: int, steps: int, device: str,
                                 budget: int = 200_000) -> tuple[float, float]:  # fmt: skip
    """Neural skill chaining's rate once every agent has a live option (trained until they
    all do, or ``budget`` population steps): ``(agent steps/s, the share of agents with a
    live option when timed)``."""
    from skillchain_torch.trainers import PopulationTrainer, TrainConfig

    cfg = TrainConfig(agent="skill-chaining", preset="paper", env=f"gymnasium:{env_id}",
                      runs=population, episodes=10_000, seed=0, device=device,
                      top_head="mlp", option_head="mlp", initiation="mlp")  # fmt: skip
    trainer = PopulationTrainer(cfg)
    done = 0
    while done < budget and not bool(trainer.agent.bank.live().any(-1).all()):
        done += 1000
        trainer.train(max_agent_steps=trainer.agent_steps + 1000 * population)
    share = float(trainer.agent.bank.live().any(-1).double().mean())
    before, start = trainer.agent_steps, time.perf_counter()
    trainer.train(max_agent_steps=before + steps * population)
    return (trainer.agent_steps - before) / (time.perf_counter() - start), share


def learner_floor(env_id: str, population: int, steps: int, device: str) -> tuple[float, float]:
    """``(agent steps/s, agent steps/s of the minibatch updates alone)``: the population's rate
    as :func:`agent_steps_per_second` times it, and the rate it would reach if everything but
    the replay learners' minibatch updates (the top level's ``ReplayTD._step``, the options'
    ``OptionReplay._learn``: sampling, forward, backward, Adam) took no time. Each agent
    updates as often as the DQN does (a minibatch every 4 of its steps), so the second number
    bounds what batching the rest of the step can reach on this device."""
    from skillchain_torch.objectives.option_replay import OptionReplay
    from skillchain_torch.objectives.replay import ReplayTD
    from skillchain_torch.trainers import PopulationTrainer, TrainConfig

    cfg = TrainConfig(agent="skill-chaining", preset="paper", env=f"gymnasium:{env_id}",
                      runs=population, episodes=10_000, seed=0, device=device,
                      top_head="mlp", option_head="mlp", initiation="mlp")  # fmt: skip
    trainer = PopulationTrainer(cfg)
    trainer.train(max_agent_steps=min(steps, 50) * population)
    inside = [0.0]

    def timed(method):
        def wrapper(*args, **kwargs):
            start = time.perf_counter()
            try:
                return method(*args, **kwargs)
            finally:
                inside[0] += time.perf_counter() - start
        return wrapper

    originals = ReplayTD._step, OptionReplay._learn
    ReplayTD._step, OptionReplay._learn = timed(originals[0]), timed(originals[1])
    try:
        before, start = trainer.agent_steps, time.perf_counter()
        trainer.train(max_agent_steps=before + steps * population)
        wall = time.perf_counter() - start
    finally:
        ReplayTD._step, OptionReplay._learn = originals
    done = trainer.agent_steps - before
    return done / wall, done / max(inside[0], 1e-9)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="MountainCar-v0")
    parser.add_argument("--populations", type=int, nargs="+", default=[1, 10, 100])
    parser.add_argument("--steps", type=int, default=1000, help="population steps timed")
    parser.add_argument("--dqn-steps", type=int, default=5000)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--live-options", action="store_true",
                        help="also time P = 100 once every agent has a live option (slow)")
    parser.add_argument("--live-budget", type=int, default=200_000,
                        help="population steps --live-options trains at most before timing")
    parser.add_argument("--floor", action="store_true",
                        help="also time P = 100's minibatch updates alone: the rate they allow")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    dqn = dqn_steps_per_second(args.env, args.dqn_steps, args.device)
    print(f"{args.env} on {args.device}, torch threads 1\n")
    print("| run | agent steps/s | / CleanRL-style DQN |\n|---|---:|---:|")
    print(f"| DQN, 1 agent | {dqn:,.0f} | 1.00x |")
    for population in args.populations:
        rate = agent_steps_per_second(args.env, population, args.steps, args.device)
        print(f"| neural skill chaining, P = {population} | {rate:,.0f} | {rate / dqn:.2f}x |")
    if args.live_options:
        rate, share = live_option_steps_per_second(args.env, 100, args.steps, args.device,
                                                   budget=args.live_budget)  # fmt: skip
        label = ("every agent with a live option" if share == 1.0 else
                 f"{100 * share:.0f}% of agents with a live option")  # fmt: skip
        print(f"| neural skill chaining, P = 100, {label} | {rate:,.0f} | {rate / dqn:.2f}x |")
    if args.floor:
        rate, bound = learner_floor(args.env, 100, args.steps, args.device)
        print(f"| neural skill chaining, P = 100 (again, learners timed) | {rate:,.0f} | "
              f"{rate / dqn:.2f}x |")
        print(f"| its minibatch updates alone, P = 100 (a bound) | {bound:,.0f} | "
              f"{bound / dqn:.2f}x |")
    # Linear flat Sarsa at P = 100 here against the same agent on Pinball (target: 15%).
    pinball = flat_steps_per_second(100, args.steps)
    here = flat_steps_per_second(100, args.steps, args.env)
    print("\n| linear flat Sarsa, P = 100 | agent steps/s | / Pinball's |\n|---|---:|---:|")
    print(f"| Pinball (pinball_simple_single) | {pinball:,.0f} | 100% |")
    print(f"| {args.env} | {here:,.0f} | {100 * here / pinball:.1f}% |")


if __name__ == "__main__":
    main()
