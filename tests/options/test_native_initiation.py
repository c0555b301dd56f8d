"""The compiled initiation classifier (native_initiation) against its torch path.

Memberships are booleans: the compiled logit and distances differ from torch's only in the last
bits, so on random states the two agree exactly. Fits agree to rounding.
"""

import doctest

import pytest
import torch

from skillchain_torch.options import InitiationClassifier, native_initiation
from skillchain_torch.options.logistic import logistic_sweeps

F64 = torch.float64
needs_native = pytest.mark.skipif(
    not native_initiation.AVAILABLE,
    reason="the compiled classifier was not built (no C compiler at install time)")


def test_built_in_ci():
    """CI installs with a compiler: there the kernel must exist (locally it may not)."""
    import os

    if os.environ.get("CI"):
        assert native_initiation.AVAILABLE, "skillchain_torch.options._initiation_native failed"


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
