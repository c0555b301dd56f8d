"""``PinballEnv``: the Pinball domain as a batched TorchRL environment.

Each of the ``batch_size`` environments is an independent copy of the original domain: it starts
at a position drawn uniformly among the map's starts from its *own* counter-based random stream
(environment ``i`` of an env seeded with ``S`` uses seed ``S + i``, so it behaves exactly like a
single environment seeded ``S + i``), and steps with :func:`~.physics.pinball_step`.

Keys (the project's contract): ``state`` raw (x, y, xdot, ydot); ``observation`` the Java
descriptor (x, y, (xdot + 1) / 2, (ydot + 1) / 2); ``action`` int64 in 0..4; and, under
``"next"``, ``reward``, ``done``, ``terminated``, ``truncated`` of shape ``[*batch, 1]``.

Besides TorchRL's ``reset``/``step``/``rollout``, the env offers a TensorDict-free API for
trainers, :meth:`PinballEnv.reset_raw` and :meth:`PinballEnv.step_raw`: building a TensorDict
costs more than a physics step of a single ball.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from skillchain_torch.rng import CounterRNG

from .grid import check_grid_size
from .maps import PinballMap, load_map
from .physics import NUM_ACTIONS, observation, pinball_step
from .render import render_frame

__all__ = ["PinballEnv", "ENV_STREAM"]

# Salt of the start-position stream, so an agent seeded S and its environment seeded S draw
# different numbers.
ENV_STREAM = 0x5EED_E5
# After a reflection a velocity component can reach sqrt(2) until the next step's clip, so the
# descriptor's velocity part lies in [(1 - sqrt 2) / 2, (1 + sqrt 2) / 2].
_OBS_VEL_LOW = (1.0 - math.sqrt(2.0)) / 2.0
_OBS_VEL_HIGH = (1.0 + math.sqrt(2.0)) / 2.0


class PinballEnv(EnvBase):
    """The Pinball domain of Konidaris & Barto (2009), batched, emitting TensorDicts.

    Args:
        map: a shipped map name (see ``MAP_NAMES``), a path to a ``.cfg`` file, or a
            :class:`~.maps.PinballMap`.
        batch_size: ``()`` for one environment, ``[P]`` for P independent ones (any shape
            whose dimensions are all >= 1). An empty batch (``[0]``) is refused with a
            ``ValueError``: it has no environment to simulate, and TorchRL's rollouts and
            collectors assume at least one.
        device: where states live (CUDA works; the physics is the same code).
        dtype: float64 by default: collisions are decided in this precision, and float32
            drifts from the original.
        max_episode_steps: truncate episodes after this many steps (``None``: never, as in
            the original).
        seed: seed of environment 0; environment ``i`` uses ``seed + i``. ``None`` draws one
            from torch's global generator.

    Every environment must be placed before it is stepped, by ``reset()`` (or
    :meth:`reset_raw`, :meth:`set_state`): stepping one that never was raises
    ``RuntimeError`` instead of moving a ball from (0, 0). TorchRL's ``rollout``,
    ``check_env_specs`` and collectors reset first.

    Example:
        >>> env = PinballEnv("pinball_simple_single", batch_size=[2], seed=0)
        >>> td = env.reset()
        >>> td["state"]
        tensor([[0.2000, 0.9000, 0.0000, 0.0000],
                [0.2000, 0.9000, 0.0000, 0.0000]], dtype=torch.float64)
        >>> td["action"] = torch.tensor([0, 4])
        >>> env.step(td)["next", "reward"].squeeze(-1)
        tensor([-5., -1.], dtype=torch.float64)
    """

    batch_locked = True

    def __init__(
        self,
        map: str | PinballMap = "pinball_simple_single",
        batch_size=(),
        device=None,
        dtype: torch.dtype = torch.float64,
        max_episode_steps: int | None = None,
        seed: int | None = None,
    ):
        if not dtype.is_floating_point:
            raise ValueError(f"dtype must be a floating-point dtype, got {dtype}")
        if max_episode_steps is not None and int(max_episode_steps) < 1:
            raise ValueError(f"max_episode_steps must be >= 1 or None, got {max_episode_steps}")
        device = torch.device("cpu") if device is None else torch.device(device)
        batch_size = torch.Size(batch_size)
        if any(d < 1 for d in batch_size):
            raise ValueError(
                f"batch_size must have every dimension >= 1, got {list(batch_size)} "
                "(an empty batch has no environment to simulate)"
            )
        super().__init__(device=device, batch_size=batch_size)
        if isinstance(map, PinballMap):
            pinball_map = map
        elif str(map).endswith(".cfg") and ("/" in str(map) or "\\" in str(map)):
            pinball_map = PinballMap.from_file(map)
        else:
            pinball_map = load_map(str(map))
        self.pinball_map = pinball_map.to(device=device, dtype=dtype)
        # Refuse, before anything large is allocated, a map whose collision grid would not fit.
        check_grid_size(self.pinball_map)
        self.dtype = dtype
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        self.num_envs = math.prod(self.batch_size)
        n = self.num_envs
        # Mutable simulator state lives in a plain holder: assigning tensors to attributes of
        # an nn.Module (EnvBase is one) costs more than a whole single-ball physics step.
        self._sim = SimpleNamespace(
            state=torch.zeros(n, 4, dtype=dtype, device=device),
            step_count=torch.zeros(n, dtype=torch.long, device=device),
            done=torch.ones(n, dtype=torch.bool, device=device),
            # Until every environment has been reset (or set_state), step_raw refuses to run;
            # `placed` marks those that have, and `ready` spares the hot path the tensor test.
            placed=torch.zeros(n, dtype=torch.bool, device=device),
            ready=False,
        )
        self._flat = self.batch_size == (n,)  # no reshapes needed at the boundary
        self._make_specs()
        if seed is None:
            seed = int(torch.randint(0, 2**31 - 1, ()).item())
        self.set_seed(seed)

    # ----------------------------------------------------------------- specs
    def _make_specs(self) -> None:
        shape, dev, dt = self.batch_size, self.device, self.dtype
        low = torch.tensor([0.0, 0.0, _OBS_VEL_LOW, _OBS_VEL_LOW], dtype=dt, device=dev)
        high = torch.tensor([1.0, 1.0, _OBS_VEL_HIGH, _OBS_VEL_HIGH], dtype=dt, device=dev)
        self.observation_spec = Composite(
            state=Unbounded(shape=(*shape, 4), dtype=dt, device=dev),
            observation=Bounded(
                low=low.expand(*shape, 4), high=high.expand(*shape, 4), dtype=dt, device=dev
            ),
            shape=shape,
            device=dev,
        )
        self.action_spec = Categorical(NUM_ACTIONS, shape=shape, dtype=torch.int64, device=dev)
        self.reward_spec = Unbounded(shape=(*shape, 1), dtype=dt, device=dev)
        self.done_spec = Composite(
            done=Categorical(2, shape=(*shape, 1), dtype=torch.bool, device=dev),
            terminated=Categorical(2, shape=(*shape, 1), dtype=torch.bool, device=dev),
            truncated=Categorical(2, shape=(*shape, 1), dtype=torch.bool, device=dev),
            shape=shape,
            device=dev,
        )

    def _set_seed(self, seed: int | None) -> None:
        self.seed = int(seed)
        self._sim.rng = CounterRNG.from_seed(
            self.seed, self.num_envs, stream=ENV_STREAM, device=self._sim.state.device
        )

    # ----------------------------------------------------------------- raw API
    @property
    def state(self) -> torch.Tensor:
        """Current raw states, ``[*batch, 4]`` (a copy)."""
        return self._shape(self._sim.state.clone(), 4)

    @property
    def step_count(self) -> torch.Tensor:
        """Steps since each environment's last reset, ``[*batch]``."""
        return self._shape(self._sim.step_count.clone())

    def _shape(self, x: torch.Tensor, *tail: int) -> torch.Tensor:
        return x if self._flat else x.reshape((*self.batch_size, *tail))

    def set_state(self, state: torch.Tensor) -> None:
        """Place the balls at raw ``state`` ``[*batch, 4]`` (for hand-built situations).

        Example:
            >>> env = PinballEnv(batch_size=[1], seed=0)
            >>> env.set_state(torch.tensor([[0.5, 0.5, 0.1, 0.0]], dtype=torch.float64))
        """
        sim = self._sim
        state = torch.as_tensor(state, dtype=self.dtype, device=sim.state.device)
        if state.shape != (*self.batch_size, 4):
            raise ValueError(
                f"state must have shape {(*self.batch_size, 4)}, got {tuple(state.shape)}"
            )
        if not bool(torch.isfinite(state).all()):
            raise ValueError(f"state must be finite, got {state.tolist()}")
        sim.state = state.reshape(self.num_envs, 4).clone()
        sim.step_count.zero_()
        sim.done.zero_()
        sim.placed.fill_(True)
        sim.ready = True

    def reset_raw(self, mask: torch.Tensor | None = None) -> torch.Tensor:
        """Restart the environments where ``mask`` is True (all if ``None``); observations.

        Each restarted environment draws its start from its own stream and starts at rest.
        """
        sim, n = self._sim, self.num_envs
        if mask is None:
            mask = torch.ones(n, dtype=torch.bool, device=sim.state.device)
        else:
            mask = torch.as_tensor(mask, device=sim.state.device).reshape(n).to(torch.bool)
        starts = self.pinball_map.starts
        choice = sim.rng.integers(1, starts.shape[0], mask=mask)[:, 0]
        fresh = torch.cat([starts[choice], torch.zeros_like(starts[choice])], dim=-1)
        sim.state = torch.where(mask[:, None], fresh, sim.state)
        sim.step_count = torch.where(mask, 0, sim.step_count)
        sim.done = sim.done & ~mask
        if not sim.ready:
            sim.placed = sim.placed | mask
            sim.ready = bool(sim.placed.all())
        return self._shape(observation(sim.state), 4)

    def step_raw(self, action: torch.Tensor):
        """Step every environment: ``(observation, reward, terminated, truncated)``.

        Shapes are ``[*batch, 4]`` and ``[*batch]``. Out-of-range or non-integer actions raise
        ``ValueError``.
        """
        sim = self._sim
        if not sim.ready:
            self._refuse_unplaced()
        action = torch.as_tensor(action, device=sim.state.device)
        if action.shape != self.batch_size:
            raise ValueError(
                f"action must have shape {tuple(self.batch_size)}, got {tuple(action.shape)}"
            )
        if not self._flat:
            action = action.reshape(self.num_envs)
        state, reward, terminated = pinball_step(sim.state, action, self.pinball_map)
        sim.state = state
        sim.step_count = sim.step_count + 1
        if self.max_episode_steps is None:
            truncated = torch.zeros_like(terminated)
            sim.done = terminated
        else:
            truncated = (sim.step_count >= self.max_episode_steps) & ~terminated
            sim.done = terminated | truncated
        return (
            self._shape(observation(state), 4),
            self._shape(reward),
            self._shape(terminated),
            self._shape(truncated),
        )

    def _refuse_unplaced(self):
        unplaced = (~self._sim.placed).nonzero()[:, 0].tolist()
        shown = ", ".join(map(str, unplaced[:8])) + (", ..." if len(unplaced) > 8 else "")
        raise RuntimeError(
            f"PinballEnv: call reset() before step(): {len(unplaced)} of {self.num_envs} "
            f"environments (flat indices {shown}) have never been reset, and stepping them "
            "would move a ball from (0, 0); reset them (reset(), reset_raw() or set_state())"
        )

    # ----------------------------------------------------------------- TorchRL API
    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        mask = None
        if tensordict is not None and "_reset" in tensordict.keys():
            mask = tensordict.get("_reset").reshape(self.num_envs)
        obs = self.reset_raw(mask)
        done = self._sim.done.reshape(*self.batch_size, 1)
        return TensorDict(
            {
                "state": self.state,
                "observation": obs,
                "done": done.clone(),
                "terminated": done.clone(),
                "truncated": torch.zeros_like(done),
            },
            batch_size=self.batch_size,
            device=self.device,
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        obs, reward, terminated, truncated = self.step_raw(tensordict.get("action"))
        shape = (*self.batch_size, 1)
        return TensorDict(
            {
                "state": self.state,
                "observation": obs,
                "reward": reward.reshape(shape),
                "done": (terminated | truncated).reshape(shape),
                "terminated": terminated.reshape(shape),
                "truncated": truncated.reshape(shape),
            },
            batch_size=self.batch_size,
            device=self.device,
        )

    # ----------------------------------------------------------------- rendering
    def render(self, index: int = 0, size: int = 400):
        """An RGB frame ``[size, size, 3]`` uint8 of environment ``index`` (flat index)."""
        return render_frame(self.pinball_map, self._sim.state[index].cpu(), size=size)

    def __repr__(self) -> str:
        return (
            f"PinballEnv(map={self.pinball_map.name!r}, batch_size={tuple(self.batch_size)}, "
            f"device={self.device}, dtype={self.dtype}, "
            f"max_episode_steps={self.max_episode_steps}, seed={self.seed})"
        )
