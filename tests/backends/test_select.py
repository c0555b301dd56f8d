"""The one switch (backends/select.py) and the same-bits kernels it turns off."""

import doctest

import pytest
import torch

import skillchain_torch.backends
from skillchain_torch.backends import discovery, fourier, native, rng, select
from skillchain_torch.features import FourierBasis
from skillchain_torch.rng import CounterRNG


@pytest.mark.parametrize("module", [skillchain_torch.backends, select, fourier, rng, native])
def test_doctest(module):
    assert doctest.testmod(module).failed == 0


def test_same_bits_kernels_off_gives_the_same_bits_and_restores_the_switches():
    x = torch.rand(5, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    on = FourierBasis(4, 3)(x), CounterRNG(torch.arange(3)).uniform(4)
    with select.same_bits_kernels(False):
        assert not (fourier.NATIVE or rng.NATIVE or discovery.NATIVE)
        off = FourierBasis(4, 3)(x), CounterRNG(torch.arange(3)).uniform(4)
    assert (fourier.NATIVE, rng.NATIVE, discovery.NATIVE) == (
        fourier.AVAILABLE, rng.AVAILABLE, discovery.AVAILABLE)
    for a, b in zip(on, off):
        assert torch.equal(a, b)
