"""``constrain_nearest``: a learned initiation set leaves out the states nearer to a stored
failure's start than to any stored positive (the paper: failed start states "were then removed
from the initiation set"), on every path: membership, images and save/load."""

import pytest
import torch

from skillchain_torch.backends import initiation as native_initiation
from skillchain_torch.options import InitiationClassifier, OptionBank

F64 = torch.float64
PATHS = [False, pytest.param(True, marks=pytest.mark.skipif(
    not native_initiation.AVAILABLE, reason="compiled classifier not built"))]


def _learned(nearest: bool, native: bool, population: int = 1) -> InitiationClassifier:
    """Slot 0: positives along x = 0.30 .. 0.70 (y = 0.5), one failure at x = 0.5, y = 0.52;
    a fitted, constrained set (velocities 0.5)."""
    clf = InitiationClassifier(population=population, slots=2, capacity=64,
                               constrain_nearest=nearest)
    clf.set_native(native)
    x = torch.linspace(0.3, 0.7, 41, dtype=F64)
    positives = torch.stack([x, torch.full_like(x, 0.5), *[torch.full_like(x, 0.5)] * 2], 1)
    failure = torch.tensor([[0.5, 0.52, 0.5, 0.5]], dtype=F64)
    for p in range(population):
        clf.add_examples(p, 0, positives, torch.ones(41))
        clf.add_examples(p, 0, failure, torch.zeros(1))
    clf.fit()
    clf.constrain(torch.tensor([[True, False]] * population))
    return clf


def _probe(y: float, x: float = 0.5) -> torch.Tensor:
    return torch.tensor([[x, y, 0.5, 0.5]], dtype=F64)


@pytest.mark.parametrize("native", PATHS)
def test_a_state_nearer_a_failure_leaves_the_set(native):
    plain, nearest = _learned(False, native), _learned(True, native)
    at_failure = _probe(0.525)  # 0.005 from the failure, 0.025 from the nearest positive
    assert bool(plain.contains(at_failure)[0, 0])
    assert not bool(nearest.contains(at_failure)[0, 0])
    on_route = _probe(0.5, x=0.41)  # on the positives' line, far from the failure
    assert bool(nearest.contains(on_route)[0, 0])
    beside = _probe(0.5)  # the positive at x = 0.5 is nearer than the failure (0.02)
    assert bool(nearest.contains(beside)[0, 0])
    assert bool(nearest.contains(at_failure)[0, 1])  # another slot: untouched


@pytest.mark.parametrize("native", PATHS)
def test_images_and_membership_agree(native):
    clf = _learned(True, native)
    g = torch.linspace(0.35, 0.65, 31, dtype=F64)
    points = torch.stack([g.repeat_interleave(31), g.repeat(31), *[torch.full((961,), 0.5,
                          dtype=F64)] * 2], 1)  # fmt: skip
    drawn = clf.contains_points(0, 0, points)
    one_by_one = torch.tensor([bool(clf.contains(points[i:i + 1])[0, 0]) for i in range(961)])
    assert torch.equal(drawn, one_by_one)
    assert 0 < int((~drawn & _learned(False, native).contains_points(0, 0, points)).sum())


def test_torch_and_compiled_agree_in_a_population():
    if not native_initiation.AVAILABLE:
        pytest.skip("compiled classifier not built")
    paths = [_learned(True, native, population=3) for native in (False, True)]
    gen = torch.Generator().manual_seed(1)
    for _ in range(200):
        obs = 0.4 + 0.2 * torch.rand(3, 4, dtype=F64, generator=gen)
        obs[:, 2:] = 0.5
        assert torch.equal(paths[0].contains(obs), paths[1].contains(obs))


def test_saved_with_the_bank(tmp_path):
    bank = OptionBank.build(population=1, slots=2, order=1, constrain_nearest=True)
    bank.save(tmp_path / "options.pt")
    assert OptionBank.load(tmp_path / "options.pt").classifier.constrain_nearest
