"""Fourier and polynomial features: closed forms, counts, ordering, population invariance."""

import doctest
import importlib
import math

import pytest
import torch

from skillchain_torch.features import FourierBasis, PolynomialFeatures

F64 = torch.float64


def test_doctests():
    for name in ("fourier", "polynomial"):
        module = importlib.import_module(f"skillchain_torch.features.{name}")
        assert doctest.testmod(module).failed == 0


@pytest.mark.parametrize(("dim", "order", "count"), [(4, 4, 625), (4, 5, 1296), (4, 3, 256)])
def test_fourier_counts_from_the_paper(dim, order, count):
    basis = FourierBasis(dim, order)
    assert basis.num_features == count
    assert basis.coefficients.shape == (count, dim)
    assert basis(torch.rand(3, dim, dtype=F64)).shape == (3, count)


def test_fourier_order1_dim2_closed_form():
    x = torch.rand(10, 2, dtype=F64)
    x1, x2 = x[:, 0], x[:, 1]
    expected = torch.stack(
        [torch.ones_like(x1), torch.cos(math.pi * x2), torch.cos(math.pi * x1),
         torch.cos(math.pi * (x1 + x2))],
        dim=-1,
    )  # fmt: skip
    assert torch.allclose(FourierBasis(2, 1)(x), expected, rtol=0, atol=1e-15)


def test_fourier_order2_dim1_and_dim3_entries():
    x = torch.rand(6, 1, dtype=F64)
    expected = torch.cat(
        [torch.ones_like(x), torch.cos(math.pi * x), torch.cos(2 * math.pi * x)], -1
    )
    assert torch.allclose(FourierBasis(1, 2)(x), expected, rtol=0, atol=1e-15)
    basis = FourierBasis(3, 2)
    y = torch.rand(4, 3, dtype=F64)
    index = 1 * 9 + 0 * 3 + 2  # c = (1, 0, 2): last dim varies fastest
    assert basis.coefficients[index].tolist() == [1.0, 0.0, 2.0]
    closed = torch.cos(math.pi * (y[:, 0] + 2 * y[:, 2]))
    assert torch.allclose(basis(y)[:, index], closed, rtol=0, atol=1e-14)


def test_fourier_coefficients_are_lexicographic():
    c = FourierBasis(3, 3).coefficients.to(torch.int64)
    as_numbers = (c * torch.tensor([16, 4, 1])).sum(-1)
    assert torch.equal(as_numbers, torch.arange(64))


def test_fourier_step_size_scale():
    scale = FourierBasis(2, 1).step_size_scale()
    assert torch.allclose(scale, torch.tensor([1.0, 1.0, 1.0, 2**-0.5], dtype=F64))
    basis = FourierBasis(4, 3)
    norms = basis.coefficients.norm(dim=-1)
    expected = torch.where(norms == 0, torch.ones_like(norms), 1 / norms)
    assert torch.allclose(basis.step_size_scale(), expected)


def test_polynomial_closed_forms():
    x = torch.tensor([[2.0, 3.0], [-1.0, 0.5]], dtype=F64)
    a, b = x[:, 0], x[:, 1]
    expected = torch.stack([torch.ones_like(a), a, b, a * a, a * b, b * b], -1)
    assert torch.equal(PolynomialFeatures(2, 2)(x), expected)
    assert PolynomialFeatures(4, 2).num_features == 15
    assert PolynomialFeatures(3, 3).num_features == 20
    assert torch.equal(
        PolynomialFeatures(3, 0)(torch.rand(2, 3, dtype=F64)), torch.ones(2, 1, dtype=F64)
    )
    assert torch.equal(
        PolynomialFeatures(3, 1)(x.new_tensor([[4.0, 5.0, 6.0]])), x.new_tensor([[1.0, 4, 5, 6]])
    )


def test_polynomial_exponents_match_forward():
    poly = PolynomialFeatures(4, 3)
    x = torch.rand(7, 4, dtype=F64) + 0.5
    by_pow = (x[:, None, :] ** poly.exponents).prod(-1)
    assert torch.allclose(poly(x), by_pow, rtol=1e-14)
    degrees = poly.exponents.sum(-1)
    assert bool((degrees[1:] >= degrees[:-1]).all())  # graded by total degree
    assert len({tuple(e) for e in poly.exponents.tolist()}) == poly.num_features


@pytest.mark.parametrize("make", [lambda: FourierBasis(4, 5), lambda: PolynomialFeatures(4, 2)])
def test_population_invariance(make):
    features = make()
    x = torch.rand(5, 4, dtype=F64, generator=torch.Generator().manual_seed(0))
    together = features(x)
    for p in range(5):
        assert torch.equal(features(x[p : p + 1])[0], together[p])
        assert torch.equal(features(x[p]), together[p])  # no batch dim at all
    big = torch.rand(400, 4, dtype=F64, generator=torch.Generator().manual_seed(1))
    assert torch.equal(features(big)[123], features(big[123:124])[0])


@pytest.mark.parametrize("make", [lambda: FourierBasis(4, 3), lambda: PolynomialFeatures(4, 2)])
def test_buffers_only_and_dtype_moves(make):
    features = make()
    assert list(features.parameters()) == []
    assert len(features.state_dict()) >= 1
    x = torch.rand(3, 4)
    assert features(x).dtype == F64  # float32 input is promoted to the basis dtype
    single = features.to(torch.float32)
    assert single(x).dtype == torch.float32
    assert "num_features" in repr(features)


def test_invalid_arguments():
    with pytest.raises(ValueError):
        FourierBasis(0, 3)
    with pytest.raises(ValueError):
        PolynomialFeatures(2, -1)


@pytest.mark.parametrize(("dim", "order"), [(1, 0), (1, 3), (2, 1), (3, 2), (4, 3), (4, 4), (4, 5)])
def test_fourier_compiled_arguments_are_the_torch_bits(dim, order):
    """On the CPU in float64 the arguments are formed in C; the features must not change."""
    from skillchain_torch.backends import fourier
    from skillchain_torch.backends.select import same_bits_kernels

    gen = torch.Generator().manual_seed(dim * 10 + order)
    # in and outside [0, 1] (velocities after reflections), batched and strided
    x = torch.rand(3, 37, dim + 1, dtype=torch.float64, generator=gen)[..., :dim] * 1.5 - 0.25
    basis = FourierBasis(dim, order)
    compiled = basis(x)
    with same_bits_kernels(False):  # a basis built without the kernel: the torch path
        torch_basis = FourierBasis(dim, order)
    assert basis._kernel is not None or not fourier.AVAILABLE
    assert torch_basis._kernel is None
    assert torch.equal(compiled, torch_basis(x))
    assert compiled.shape == (3, 37, (order + 1) ** dim)
    if not fourier.AVAILABLE:
        pytest.skip("the compiled arguments were not built (no C compiler at install time)")
