"""Environments other than Pinball: Gymnasium ids through TorchRL's ``GymEnv``, any TorchRL env.

Skill chaining needs a bounded vector observation (its Fourier features and initiation sets
live in the unit box) and discrete actions. Both come from the env's specs and nowhere else:
:func:`read_specs` returns the observation size, its bounds and the action count, and asks for
bounds (``--obs-bounds``) in one line where the spec lacks them or leaves them infinite, never
a silent default. The goal event is the env's ``terminated`` flag.

``--env gymnasium:ID`` makes ``GymEnv(ID)``; ``--env gymnasium:MODULE:ID`` imports ``MODULE``
first (Gymnasium's ``module:id`` form), so an env registered by the user's own module works.

Example:
    >>> env = make_env("gymnasium:MountainCar-v0")
    >>> sizes = read_specs(env)
    >>> sizes.obs_dim, sizes.num_actions, [round(x, 2) for x in sizes.low.tolist()]
    (2, 3, [-1.2, -0.07])
    >>> parse_bounds("-1:1,0:2", 2).tolist()
    [[-1.0, 1.0], [0.0, 2.0]]
    >>> read_specs(env, obs_bounds="0:1")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: --obs-bounds gives 1 pairs LOW:HIGH, the observation has 2 dims ...
"""

from __future__ import annotations

import importlib
import math
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["EnvSizes", "PREFIX", "make_env", "parse_bounds", "read_specs"]

PREFIX = "gymnasium:"


@dataclass(frozen=True)
class EnvSizes:
    """What the agents need of an env: ``obs_dim`` (D), ``num_actions`` (A), and the
    observation's bounds ``low``/``high`` ``[D]`` (float64), which map it onto ``[0, 1]^D``."""

    obs_dim: int
    num_actions: int
    low: Tensor
    high: Tensor

    def scale(self, obs: Tensor) -> Tensor:
        """``(obs - low) / (high - low)`` in float64: the observation in the unit box."""
        obs = obs.to(torch.float64)
        return (obs - self.low.to(obs.device)) / (self.high - self.low).to(obs.device)


def make_env(spec: str, seed: int | None = None, device: str | torch.device = "cpu"):
    """A TorchRL env for ``spec`` (``"gymnasium:ID"`` or ``"gymnasium:MODULE:ID"``) with
    integer actions, seeded with ``seed`` when given. Raises ``ValueError`` (one line) for a
    malformed spec, a module that does not import, or an id Gymnasium does not know."""
    from torchrl.envs import GymEnv

    if not isinstance(spec, str) or not spec.startswith(PREFIX) or spec == PREFIX:
        raise ValueError(f"--env must be 'gymnasium:ID' or 'gymnasium:MODULE:ID', got {spec!r}")
    rest = spec[len(PREFIX):]
    module, _, env_id = rest.rpartition(":")
    if module:
        try:
            importlib.import_module(module)
        except ImportError as error:
            raise ValueError(f"--env {spec}: module {module!r} does not import ({error})") from None
    try:
        env = GymEnv(env_id, categorical_action_encoding=True, device=device)
    except Exception as error:  # gymnasium raises several types for unknown or broken ids
        reason = " ".join(str(error).split())[:200]
        raise ValueError(f"--env {spec}: Gymnasium cannot make {env_id!r} ({reason})") from None
    if seed is not None:
        env.set_seed(int(seed))
    return env


def parse_bounds(text: str, dim: int) -> Tensor:
    """``"LOW:HIGH,LOW:HIGH,..."`` (one pair per observation dim) as ``[dim, 2]`` float64."""
    pairs = [p for p in text.split(",") if p.strip()]
    if len(pairs) != dim:
        raise ValueError(f"--obs-bounds gives {len(pairs)} pairs LOW:HIGH, the observation has "
                         f"{dim} dims (e.g. {','.join(['-1:1'] * dim)})")  # fmt: skip
    out = []
    for i, pair in enumerate(pairs):
        try:
            low, high = (float(x) for x in pair.split(":"))
        except ValueError:
            raise ValueError(f"--obs-bounds pair {i} is {pair!r}, not LOW:HIGH") from None
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise ValueError(f"--obs-bounds pair {i} is {pair!r}: need finite LOW < HIGH")
        out.append((low, high))
    return torch.tensor(out, dtype=torch.float64)


def read_specs(env, obs_bounds: str | None = None, key: str = "observation") -> EnvSizes:
    """The env's :class:`EnvSizes` from its specs (``obs_bounds`` replaces the bounds)."""
    specs = env.observation_spec
    if key not in specs.keys():
        raise ValueError(f"the env's observation spec has no {key!r} entry (it has "
                         f"{', '.join(map(str, specs.keys()))}): skill chaining needs one "
                         "vector observation")  # fmt: skip
    spec = specs[key]
    if len(spec.shape) != 1:
        raise ValueError(f"the observation must be a vector, its spec has shape "
                         f"{tuple(spec.shape)}")  # fmt: skip
    dim = int(spec.shape[0])
    action = env.action_spec
    n = getattr(getattr(action, "space", None), "n", None)
    if n is None:
        raise ValueError(f"skill chaining needs discrete actions; the env's action spec is "
                         f"{type(action).__name__}")  # fmt: skip
    if obs_bounds is not None:
        bounds = parse_bounds(obs_bounds, dim)
        low, high = bounds[:, 0], bounds[:, 1]
    else:
        space = getattr(spec, "space", None)
        low, high = getattr(space, "low", None), getattr(space, "high", None)
        if low is None or high is None or not bool(torch.isfinite(low).all()
                                                    and torch.isfinite(high).all()):
            kind = type(spec).__name__
            raise ValueError(f"the env's observation spec gives no finite bounds ({kind}); "
                             f"pass them: --obs-bounds {','.join(['LOW:HIGH'] * dim)}")
        low, high = low.to(torch.float64).reshape(dim), high.to(torch.float64).reshape(dim)
    return EnvSizes(dim, int(n), low, high)
