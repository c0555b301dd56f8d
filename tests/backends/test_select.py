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
        assert select.same_bits_kernel("fourier") is None
        assert select.same_bits_kernel("rng") is None
        assert select.discovery_rules(True).__name__ == "SkillChaining"
        off = FourierBasis(4, 3)(x), CounterRNG(torch.arange(3)).uniform(4)
    # as before after the block
    assert (select.same_bits_kernel("fourier") is not None) is fourier.AVAILABLE
    assert (select.same_bits_kernel("rng") is not None) is rng.AVAILABLE
    assert (select.discovery_rules(True).__name__ == "CompiledSkillChaining") is discovery.AVAILABLE
    for a, b in zip(on, off):
        assert torch.equal(a, b)


def _backend_imports(path):
    """``(line, module)`` of every import of a ``skillchain_torch.backends`` module in ``path``."""
    import ast

    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            if node.module == "skillchain_torch.backends":
                found += [(node.lineno, f"{node.module}.{a.name}") for a in node.names]
            elif node.module.startswith("skillchain_torch.backends."):
                found.append((node.lineno, node.module))
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names
                      if a.name.startswith("skillchain_torch.backends")]  # fmt: skip
    return found


def test_outside_backends_only_the_selection_module_is_imported():
    # Issue 51: a kernel is chosen once, by backends/select.py; every other file reaches the
    # kernels only through what select hands it (the env's own compiled physics stays in envs/).
    from pathlib import Path

    root = Path(skillchain_torch.__file__).resolve().parent.parent
    files = [p for top in ("skillchain_torch", "trainers", "envs")
             for p in (root / top).rglob("*.py")
             if "backends" not in p.relative_to(root).parts]  # fmt: skip
    assert len(files) > 50
    wrong = [f"{p.relative_to(root)}:{line} imports {module}" for p in files
             for line, module in _backend_imports(p)
             if module != "skillchain_torch.backends.select"]  # fmt: skip
    assert wrong == []


def test_a_classifier_takes_its_kernel_from_select_once():
    from skillchain_torch.backends.compiled_initiation import CompiledInitiation
    from skillchain_torch.options import InitiationClassifier

    class Mine(InitiationClassifier):
        pass

    clf = InitiationClassifier(population=1, slots=2, capacity=8)
    assert clf._kernel is None and not clf.native  # the torch path until an agent asks
    from skillchain_torch.backends import initiation

    assert clf.set_native(None) is initiation.AVAILABLE
    assert isinstance(clf._kernel, CompiledInitiation) is initiation.AVAILABLE
    assert Mine(population=1, slots=2, capacity=8).set_native(None) is False
    with pytest.raises(ValueError, match="the initiation classifier is Mine"):
        Mine(population=1, slots=2, capacity=8).set_native(True)
    clf.to(torch.float32)  # off float64: the kernel no longer applies
    assert clf._kernel is None
