"""The compiled initiation classifier (backends/initiation.py) against its torch path.

Memberships are booleans: the compiled logit and distances differ from torch's only in the last
bits, so on random states the two agree exactly. Fits agree to rounding.
"""

import doctest
import functools

import pytest
import torch

from skillchain_torch.backends import initiation as native_initiation
from skillchain_torch.options import InitiationClassifier
from skillchain_torch.options.logistic import logistic_sweeps

F64 = torch.float64
needs_native = pytest.mark.skipif(
    not native_initiation.AVAILABLE,
    reason="the compiled classifier was not built (no C compiler at install time)")


def test_built_in_ci():
    """CI installs with a compiler: there the kernel must exist (locally it may not)."""
    import os

    if os.environ.get("CI"):
        assert native_initiation.AVAILABLE, "skillchain_torch.backends._initiation failed"


def test_doctest():
    assert doctest.testmod(native_initiation).failed == 0


def gen(seed):
    return torch.Generator().manual_seed(seed)


def filled(population, slots, capacity, seed, **kwargs) -> InitiationClassifier:
    """A classifier with random stores, weights, and a mix of untrained, trained and
    constrained slots."""
    g = gen(seed)
    clf = InitiationClassifier(population, slots, capacity=capacity, seed=seed, **kwargs)
    for p in range(population):
        for k in range(slots):
            n = int(torch.randint(1, 2 * capacity, (1,), generator=g))
            x = torch.rand(n, 4, dtype=F64, generator=g)
            clf.add_examples(p, k, x, x[:, 0] + 0.3 * torch.rand(n, dtype=F64, generator=g) > 0.6)
    clf.fit()
    with torch.no_grad():
        clf.weight.add_(torch.randn(clf.weight.shape, dtype=F64, generator=g))
    clf.trained &= torch.rand(population, slots, generator=g) < 0.8
    clf.constrain(torch.rand(population, slots, generator=g) < 0.5)
    return clf


@needs_native
@pytest.mark.parametrize("dims", [None, (0, 1), (3,)])
@pytest.mark.parametrize("distance", [0.1, 0.3])
def test_contains_equals_torch(dims, distance):
    clf = filled(6, 5, capacity=40, seed=3, distance_dims=dims, distance=distance)
    g = gen(11)
    seen = torch.zeros(2, dtype=torch.int64)
    for _ in range(200):
        obs = torch.rand(6, 4, dtype=F64, generator=g)
        clf.set_native(False)
        expected = clf.contains(obs)
        clf.set_native(True)
        got = clf.contains(obs)
        assert torch.equal(got, expected)
        seen += torch.stack([expected.sum(), (~expected).sum()])
    assert bool((seen > 100).all())  # both answers were exercised


@needs_native
@pytest.mark.parametrize("balanced", [False, True])
def test_sweeps_agree_with_torch(balanced):
    g = gen(5)
    M, L, F = 7, 24, 15
    x = torch.rand(M, L, F, dtype=F64, generator=g)
    labels = torch.rand(M, L, generator=g) < 0.4
    stored = torch.arange(L) < torch.randint(1, L + 1, (M, 1), generator=g)  # empty tails
    params = torch.randn(M, F + 1, dtype=F64, generator=g)
    expected = logistic_sweeps(x, labels, stored, params, 0.1, 100, balanced)
    got = native_initiation.logistic_sweeps(x, labels, stored, params, 0.1, 100, balanced)
    torch.testing.assert_close(got, expected, rtol=1e-10, atol=1e-12)
    assert not torch.equal(got, params)  # the sweeps moved them


@needs_native
def test_fit_uses_the_compiled_sweeps_and_agrees():
    torch_fit, native_fit = filled(3, 4, 64, seed=1), filled(3, 4, 64, seed=1)
    native_fit.set_native(True)
    x = torch.rand(30, 4, dtype=F64, generator=gen(2))
    for clf in (torch_fit, native_fit):
        clf.add_examples(1, 2, x, x[:, 1] > 0.5)
        clf.fit()
    torch.testing.assert_close(native_fit.weight, torch_fit.weight, rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(native_fit.bias, torch_fit.bias, rtol=1e-10, atol=1e-12)


def test_set_native_errors_name_the_reason():
    clf = InitiationClassifier(1, 2, dtype=torch.float32)
    with pytest.raises(ValueError, match="float64"):
        clf.set_native(True)
    assert clf.set_native(None) is False  # the default simply stays on torch


@needs_native
def test_leaving_the_cpu_or_float64_turns_it_off():
    clf = InitiationClassifier(1, 2)
    assert clf.set_native(None) is True
    clf.to(torch.float32)
    assert clf.native is False
    clf.contains(torch.rand(1, 4))  # the torch path answers



@needs_native
@pytest.mark.parametrize("replacement", ["reservoir", "ring"])
@pytest.mark.parametrize("centered", [False, True])
@pytest.mark.parametrize("balanced", [False, True])
def test_compiled_stores_and_fits_equal_the_compiled_sweeps_bit_for_bit(replacement, centered,
                                                                       balanced):
    """add_examples and fit in one compiled pass each give the torch path's stores
    (store_places, the reservoir's draws included: batches overflow the capacity of 16) and,
    around the same compiled sweeps, its weights and bookkeeping, bit for bit."""
    kwargs = dict(capacity=16, seed=7, replacement=replacement, centered=centered,
                  balanced=balanced)  # fmt: skip
    split = InitiationClassifier(3, 4, **kwargs)  # torch stores and fit, compiled sweeps
    split._fit_slots = functools.partial(_compiled_sweeps, split)
    fused = InitiationClassifier(3, 4, **kwargs)
    fused.set_native(True)
    g = gen(4)
    for _ in range(12):
        n = int(torch.randint(1, 30, (1,), generator=g))
        agents = torch.randint(0, 3, (n,), generator=g)
        slots = torch.randint(0, 4, (n,), generator=g)
        x = torch.rand(n, 4, dtype=F64, generator=g)
        labels = x[:, 2] > 0.4
        assert torch.equal(fused.add_examples(agents, slots, x, labels),
                           split.add_examples(agents, slots, x, labels))  # fmt: skip
        for name in ("examples", "labels", "count", "seen", "dirty"):
            assert torch.equal(getattr(fused, name), getattr(split, name)), name
        mask = torch.rand(3, 4, generator=g) < 0.7
        assert torch.equal(fused.fit(mask), split.fit(mask))
        for name in ("weight", "bias", "sweeps_done", "trained", "dirty"):
            assert torch.equal(getattr(fused, name), getattr(split, name)), name
    assert int(fused.seen.max()) > 16  # the reservoir (or ring) replaced examples
    assert fused.sweeps_done.unique().numel() > 1  # the masks left some slots out


def _compiled_sweeps(clf, pi, ki, length):
    """InitiationClassifier._fit_slots with the compiled sweeps."""
    params = native_initiation.logistic_sweeps(
        clf.phi(clf.examples[pi, ki, :length]), clf.labels[pi, ki, :length],
        torch.arange(length) < clf.count[pi, ki][:, None],
        torch.cat([clf.weight[pi, ki], clf.bias[pi, ki, None]], dim=-1), clf.lr, clf.sweeps,
        clf.balanced)  # fmt: skip
    clf.weight[pi, ki] = params[:, :-1]
    clf.bias[pi, ki] = params[:, -1]


@needs_native
def test_compiled_store_rejects_bad_indices_and_writes_nothing():
    clf = InitiationClassifier(2, 3, capacity=8)
    clf.set_native(True)
    x = torch.rand(2, 4, dtype=F64)
    with pytest.raises(ValueError, match="out of range for P=2, K=3"):
        clf.add_examples(torch.tensor([0, 2]), torch.tensor([1, 1]), x, torch.ones(2, dtype=bool))
    assert int(clf.seen.sum()) == 0 and not bool(clf.dirty.any())


@needs_native
def test_sweeps_exponential_is_within_one_ulp_of_libm():
    """exp_lane (the sweeps' exponential, native_maths.h): within 1 ulp of math.exp over the
    whole range, and libm's answers at the edges (overflow, subnormals, zero, inf, NaN)."""
    import math

    g = gen(8)
    x = torch.cat([(torch.rand(200_000, dtype=F64, generator=g) * 2 - 1) * scale
                   for scale in (1e-6, 1.0, 30.0, 709.0)])  # fmt: skip
    got = native_initiation.exp(x)
    expected = torch.tensor([math.exp(v) for v in x.tolist()], dtype=F64)
    ulp = torch.nextafter(expected, torch.tensor(math.inf, dtype=F64)) - expected
    error = ((got - expected).abs() / ulp)[expected > 0]
    assert float(error.max()) <= 1.0
    assert 0.0 < float((got != expected).double().mean()) < 0.2  # its own bits, mostly libm's
    edges = [0.0, -0.0, 1e-300, 709.78, 709.79, -708.4, -740.0, -745.1, -745.2, -746.0,
             math.inf, -math.inf]  # fmt: skip
    assert native_initiation.exp(torch.tensor(edges, dtype=F64)).tolist() == \
        [math.exp(v) if v < 709.79 else math.inf for v in edges]
    assert math.isnan(float(native_initiation.exp(torch.tensor([math.nan], dtype=F64))[0]))
