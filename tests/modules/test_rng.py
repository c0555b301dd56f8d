"""Counter-based random streams: SplitMix64 bits, the Java reference actions, per-agent streams."""

import doctest

import numpy as np
import pytest
import torch

import skillchain_torch.invariant
import skillchain_torch.rng
from skillchain_torch.backends import rng as rng_backend
from skillchain_torch.backends.select import same_bits_kernels
from skillchain_torch.rng import CounterRNG, logical_rshift, splitmix64

MASK = 2**64 - 1


def splitmix64_reference(x: int) -> int:
    """Pure-Python SplitMix64 output function on unsigned 64-bit ints."""
    z = (x + 0x9E3779B97F4A7C15) & MASK
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
    return z ^ (z >> 31)


def java_actions(seed: int, n: int) -> list[int]:
    """The action sequence of the Java reference trajectories (vectors/README.md)."""
    state, out = seed & MASK, []
    for _ in range(n):
        state = (state + 0x9E3779B97F4A7C15) & MASK
        z = state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
        z ^= z >> 31
        out.append((z >> 33) % 5)
    return out


def to_signed(u: int) -> int:
    return u - 2**64 if u >= 2**63 else u


def test_doctests():
    for module in (skillchain_torch.rng, skillchain_torch.invariant):
        assert doctest.testmod(module).failed == 0


def test_logical_shift_on_negative_int64():
    x = torch.tensor([-1, to_signed(0x8000000000000000), 12345])
    for s in (1, 11, 30, 33, 63):
        expected = [to_signed((v % 2**64) >> s) for v in x.tolist()]
        assert logical_rshift(x, s).tolist() == expected


def test_splitmix64_matches_unsigned_reference_with_wraparound():
    gen = torch.Generator().manual_seed(0)
    x = torch.randint(-(2**63), 2**63 - 1, (2000,), generator=gen, dtype=torch.int64)
    x = torch.cat([x, torch.tensor([0, 1, -1, 2**63 - 1, -(2**63)])])
    got = [v % 2**64 for v in splitmix64(x).tolist()]
    assert got == [splitmix64_reference(v % 2**64) for v in x.tolist()]


def test_seed_zero_starts_with_actions_1_2():
    bits = CounterRNG(torch.tensor([0])).bits(2)
    assert (logical_rshift(bits, 33) % 5).tolist() == [[1, 2]]
    assert java_actions(0, 2) == [1, 2]


def test_regenerates_java_reference_actions(vectors_dir):
    files = sorted(vectors_dir.glob("*_uniform_*.npz"))
    assert len(files) == 4
    seeds, actions = [], []
    for path in files:
        data = np.load(path)
        seeds.append(int(data["seed"]))
        actions.append(torch.from_numpy(data["actions"]))
    # All four at once as one population, then each alone: same actions.
    longest = max(a.numel() for a in actions)
    together = logical_rshift(CounterRNG(torch.tensor(seeds)).bits(longest), 33) % 5
    for p, (seed, expected) in enumerate(zip(seeds, actions, strict=True)):
        alone = logical_rshift(CounterRNG(torch.tensor([seed])).bits(expected.numel()), 33) % 5
        assert torch.equal(alone[0], expected)
        assert torch.equal(together[p, : expected.numel()], expected)
        assert expected[:50].tolist() == java_actions(seed, 50)


def test_population_invariance_with_masks():
    population = 5
    together = CounterRNG.from_seed(123, population, stream=3)
    alone = [CounterRNG(torch.tensor([123 + p]), stream=3) for p in range(population)]
    gen = torch.Generator().manual_seed(1)
    for step in range(20):
        mask = torch.rand(population, generator=gen) < 0.6
        high = torch.randint(1, 9, (population,), generator=gen)
        kind = step % 3
        if kind == 0:
            out = together.uniform(4, mask=mask)
        elif kind == 1:
            out = together.integers(3, high, mask=mask)
        else:
            out = together.bits(2, mask=mask)
        for p, rng in enumerate(alone):
            m = mask[p : p + 1]
            if kind == 0:
                mine = rng.uniform(4, mask=m)
            elif kind == 1:
                mine = rng.integers(3, high[p : p + 1], mask=m)
            else:
                mine = rng.bits(2, mask=m)
            assert torch.equal(mine[0], out[p])
            assert torch.equal(rng.counter[0], together.counter[p])


def test_counter_continuity_and_mask():
    a, b = CounterRNG.from_seed(5, 3), CounterRNG.from_seed(5, 3)
    assert torch.equal(torch.cat([a.uniform(3), a.uniform(2)], dim=1), b.uniform(5))
    rng = CounterRNG.from_seed(5, 3)
    first = rng.uniform(2, mask=torch.tensor([True, False, True]))
    assert rng.counter.tolist() == [2, 0, 2]
    second = rng.uniform(2)
    # The agent that did not advance sees the same numbers again: they were not consumed.
    assert torch.equal(second[1], first[1])
    assert not torch.equal(second[0], first[0])


def test_uniform_is_53_bit_in_unit_interval():
    u = CounterRNG.from_seed(0, 4).uniform(10_000)
    assert u.dtype == torch.float64
    assert bool((u >= 0).all()) and bool((u < 1).all())
    scaled = u * 2.0**53
    assert torch.equal(scaled, scaled.floor())
    assert abs(u.mean().item() - 0.5) < 0.01


def test_integers_bounds_and_uniformity():
    rng = CounterRNG.from_seed(9, 3)
    high = torch.tensor([1, 3, 7])
    draws = rng.integers(6000, high)
    assert bool((draws[0] == 0).all())
    for p in (1, 2):
        counts = torch.bincount(draws[p], minlength=int(high[p]))
        assert counts.numel() == int(high[p])
        expected = 6000 / int(high[p])
        assert bool(((counts - expected).abs() < 0.15 * expected).all())
    with pytest.raises(ValueError):
        rng.integers(1, 0)


def test_streams_and_seeds_are_distinct():
    seeds = torch.tensor([0, 1, 2])
    agent, resets = CounterRNG(seeds, stream=0).bits(100), CounterRNG(seeds, stream=1).bits(100)
    assert not bool((agent[:, :, None] == resets[:, None, :]).any())
    assert len(set(agent.flatten().tolist())) == agent.numel()


def test_state_dict_roundtrip():
    rng = CounterRNG.from_seed(2**64 - 3, 4, stream=2)  # seeds wrap into int64
    assert rng.seeds.tolist() == [-3, -2, -1, 0]
    rng.uniform(7, mask=torch.tensor([True, False, True, True]))
    restored = CounterRNG(torch.zeros(1, dtype=torch.int64))
    restored.load_state_dict(rng.state_dict())
    assert torch.equal(restored.uniform(5), rng.uniform(5))
    assert restored.stream == 2 and repr(restored) == "CounterRNG(population=4, stream=2)"


@pytest.mark.skipif(not rng_backend.AVAILABLE, reason="the compiled draw was not built")
@pytest.mark.parametrize("stream", [0, 1, 7])
def test_compiled_draws_equal_the_tensor_path(stream):
    """The C draw gives the tensor path's words and uniforms bit for bit, counters included."""
    seeds = torch.tensor([0, 1, -5, 2**62 + 3, -(2**63), 2**63 - 1])
    mask = torch.tensor([True, False, True, True, False, True])

    def draws(native):
        with same_bits_kernels(native):  # the kernel is taken when the generator is built
            rng = CounterRNG(seeds, stream=stream,
                             counter=torch.tensor([0, 5, 2**40, 9, 1, 2**62]))
        assert (rng._kernel is not None) is native
        out = [rng.bits(3), rng.uniform(4, mask=mask), rng.uniform(1), rng.bits(2, mask=mask)]
        return out, rng.counter

    (native_out, native_counter), (tensor_out, tensor_counter) = draws(True), draws(False)
    for a, b in zip(native_out, tensor_out):
        assert a.dtype == b.dtype and torch.equal(a, b)
    assert torch.equal(native_counter, tensor_counter)
