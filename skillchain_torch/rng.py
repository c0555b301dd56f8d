"""Counter-based random streams, one per agent (SplitMix64 on int64 tensors).

A shared ``torch.Generator`` would make agent ``p``'s random numbers depend on how many agents
draw before it, so a population run could not reproduce a single run. Here every number is a pure
function of ``(seed_p, stream, counter_p)``: draw ``t`` of agent ``p`` is
``splitmix64(key_p + t * GOLDEN_GAMMA)``, which for ``stream=0`` (``key_p = seed_p``) is exactly
the classic SplitMix64 sequence used to generate the Java Pinball reference trajectories.

Example:
    >>> import torch
    >>> rng = CounterRNG.from_seed(0, population=3)   # agents use seeds 0, 1, 2
    >>> u = rng.uniform(4)                            # [3, 4] float64 in [0, 1)
    >>> alone = CounterRNG(torch.tensor([1]))         # agent 1 on its own
    >>> torch.equal(alone.uniform(4)[0], u[1])
    True
    >>> (logical_rshift(CounterRNG(torch.tensor([0])).bits(2), 33) % 5).tolist()
    [[1, 2]]
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.backends.select import same_bits_kernel

_TWO64 = 1 << 64


def _as_int64(value: int) -> int:
    """Map an unsigned 64-bit constant to the int64 with the same bits."""
    value %= _TWO64
    return value - _TWO64 if value >= 1 << 63 else value


GOLDEN_GAMMA = _as_int64(0x9E3779B97F4A7C15)
_MIX_1 = _as_int64(0xBF58476D1CE4E5B9)
_MIX_2 = _as_int64(0x94D049BB133111EB)


def logical_rshift(x: Tensor, shift: int) -> Tensor:
    """Unsigned right shift of int64 bits (torch's ``>>`` on int64 is arithmetic)."""
    return (x >> shift) & ((1 << (64 - shift)) - 1)


def splitmix64(x: Tensor) -> Tensor:
    """SplitMix64 output function on int64 tensors, with uint64 wrap-around.

    int64 ``+`` and ``*`` wrap modulo 2^64 in two's complement, which gives the same bits as
    unsigned arithmetic; only the shifts need care (:func:`logical_rshift`).

    Example:
        >>> splitmix64(torch.tensor([0])).item() == 0xE220A8397B1DCDAF - 2**64
        True
    """
    z = x + GOLDEN_GAMMA
    z = (z ^ logical_rshift(z, 30)) * _MIX_1
    z = (z ^ logical_rshift(z, 27)) * _MIX_2
    return z ^ logical_rshift(z, 31)


def stream_key(stream: int) -> int:
    """The salt XOR-ed into the seeds of a stream; 0 for stream 0 (the plain sequence)."""
    if stream == 0:
        return 0
    return int(splitmix64(torch.tensor([_as_int64(stream)]))[0])


class CounterRNG:
    """Independent random streams for a population of P agents.

    Args:
        seeds: ``LongTensor [P]``, the seed of each agent.
        stream: salt that separates purposes (e.g. 0 for the agent's decisions, 1 for
            environment resets): two streams of the same seed share no numbers in practice.
        counter: optional ``LongTensor [P]``, the number of values each agent has drawn.

    Every draw of ``n`` values advances the counter of each agent (selected by ``mask``) by
    ``n``; values produced for agents outside ``mask`` must be discarded by the caller.

    Example:
        >>> rng = CounterRNG(torch.tensor([7, 8]), stream=1)
        >>> rng.integers(3, high=torch.tensor([5, 2])).shape
        torch.Size([2, 3])
        >>> _ = rng.uniform(2, mask=torch.tensor([True, False]))
        >>> rng.counter.tolist()
        [5, 3]
    """

    def __init__(self, seeds: Tensor, stream: int = 0, counter: Tensor | None = None):
        seeds = torch.as_tensor(seeds, dtype=torch.int64)
        if seeds.ndim != 1:
            raise ValueError(f"seeds must have shape [P], got {tuple(seeds.shape)}")
        self.seeds = seeds.clone()
        self.stream = int(stream)
        self._salt = stream_key(self.stream)
        # The compiled draws (the same bits) where built, chosen once: None, the torch path.
        self._kernel = same_bits_kernel("rng")
        self.counter = (
            torch.zeros_like(seeds) if counter is None else torch.as_tensor(counter).clone()
        )
        if self.counter.shape != self.seeds.shape:
            raise ValueError("counter must have the same shape as seeds")

    @classmethod
    def from_seed(
        cls, seed: int, population: int, stream: int = 0, device: torch.device | str | None = None
    ) -> CounterRNG:
        """Agent ``p`` of a population started with seed ``S`` uses seed ``S + p``."""
        seeds = torch.tensor([_as_int64(seed + p) for p in range(population)], device=device)
        return cls(seeds, stream=stream)

    @property
    def population(self) -> int:
        return self.seeds.shape[0]

    @property
    def device(self) -> torch.device:
        return self.seeds.device

    def _draw(self, n: int, mask: Tensor | None, uniform: bool) -> Tensor | None:
        """The compiled draw (words or uniforms, the same bits), or ``None`` where it does not
        apply."""
        kernel = self._kernel
        drawn = None if kernel is None else kernel(self.seeds, self.counter, n, mask,
                                                   self._salt, uniform)  # fmt: skip
        if drawn is None:
            return None
        out, self.counter = drawn
        return out

    def bits(self, n: int, mask: Tensor | None = None) -> Tensor:
        """Draw ``n`` raw 64-bit words per agent: ``int64 [P, n]``."""
        out = self._draw(n, mask, uniform=False)
        if out is not None:
            return out
        steps = self.counter[:, None] + torch.arange(n, device=self.device)
        keys = self.seeds ^ self._salt
        out = splitmix64(keys[:, None] + steps * GOLDEN_GAMMA)
        if mask is None:
            self.counter = self.counter + n
        else:
            self.counter = torch.where(mask.to(self.device), self.counter + n, self.counter)
        return out

    def uniform(self, n: int, mask: Tensor | None = None) -> Tensor:
        """Draw ``n`` uniforms in [0, 1) per agent from the 53 high bits: ``float64 [P, n]``."""
        out = self._draw(n, mask, uniform=True)
        if out is not None:
            return out
        # 53-bit integers convert to float64 exactly, and scaling by 2^-53 is exact too.
        return logical_rshift(self.bits(n, mask), 11).to(torch.float64) * 2.0**-53

    def integers(self, n: int, high: int | Tensor, mask: Tensor | None = None) -> Tensor:
        """Draw ``n`` integers uniform in ``[0, high)`` per agent: ``int64 [P, n]``.

        ``high`` is an int or a ``LongTensor [P]`` (each at least 1).
        """
        high = torch.as_tensor(high, dtype=torch.int64, device=self.device)
        if bool((high < 1).any()):
            raise ValueError("high must be >= 1")
        high = high.expand(self.population)[:, None]
        # u * high can round up to high for u close to 1, hence the clamp.
        draw = torch.floor(self.uniform(n, mask) * high.to(torch.float64)).to(torch.int64)
        return torch.minimum(draw, high - 1)

    def state_dict(self) -> dict[str, Tensor | int]:
        return {"seeds": self.seeds.clone(), "counter": self.counter.clone(), "stream": self.stream}

    def load_state_dict(self, state: dict[str, Tensor | int]) -> None:
        self.seeds = torch.as_tensor(state["seeds"], dtype=torch.int64).clone()
        self.counter = torch.as_tensor(state["counter"], dtype=torch.int64).clone()
        self.stream = int(state["stream"])
        self._salt = stream_key(self.stream)

    def to(self, device: torch.device | str) -> CounterRNG:
        """Move the streams to ``device`` (in place) and return ``self``."""
        self.seeds = self.seeds.to(device)
        self.counter = self.counter.to(device)
        return self

    def __repr__(self) -> str:
        return f"CounterRNG(population={self.population}, stream={self.stream})"
