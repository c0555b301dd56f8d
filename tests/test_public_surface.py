"""The package's public surface: what a new user imports first.

Import side effects (the Gymnasium ids, what ``import skillchain_torch`` loads) are checked in
a fresh interpreter, since this test session has imported everything already.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SUBPACKAGES = ["agents", "backends", "collectors", "discovery", "envs", "features", "modules",
               "objectives", "options", "policies", "trainers"]


def fresh(code: str) -> str:
    """Run ``code`` in a new interpreter (outside the repository, so the installed package is
    what it imports); its stdout."""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT.parent, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_import_registers_the_gym_ids_without_loading_torch():
    out = fresh(
        "import sys, gymnasium as gym, skillchain_torch\n"
        "ids = sorted(i for i in gym.registry if i.startswith('skillchain_torch/'))\n"
        "print(len(ids), 'torch' in sys.modules)\n"
        "env = gym.make('skillchain_torch/Pinball-SimpleSingle-v0')\n"
        "print(env.reset(seed=0)[0].tolist())\n"
    )
    assert out.splitlines() == ["6 False", "[0.2, 0.9, 0.5, 0.5]"]


def test_the_registered_ids_are_the_pinball_packages():
    out = fresh(
        "import gymnasium as gym, skillchain_torch\n"
        "from skillchain_torch.envs.pinball import GYM_IDS, MAP_NAMES\n"
        "ids = {i for i in gym.registry if i.startswith('skillchain_torch/')}\n"
        "print(ids == set(GYM_IDS), sorted(GYM_IDS.values()) == sorted(MAP_NAMES))\n"
    )
    assert out == "True True"


def test_pinball_env_imports_from_envs():
    out = fresh(
        "from skillchain_torch.envs import PinballEnv, GymPinballEnv, load_map\n"
        "from skillchain_torch.envs.pinball import PinballEnv as P\n"
        "print(PinballEnv is P, PinballEnv('pinball_box', batch_size=[2]).batch_size)\n"
    )
    assert out == "True torch.Size([2])"


def test_unknown_names_raise_attribute_error():
    import skillchain_torch
    import skillchain_torch.envs

    for module, name in ((skillchain_torch, "agentz"), (skillchain_torch.envs, "PinbalEnv")):
        with pytest.raises(AttributeError, match=name):
            getattr(module, name)


def test_all_names_the_subpackages_and_each_loads():
    import skillchain_torch

    assert sorted(skillchain_torch.__all__) == SUBPACKAGES
    out = fresh(
        "import skillchain_torch\n"
        "print(all(getattr(skillchain_torch, n).__name__ == 'skillchain_torch.' + n\n"
        "          for n in skillchain_torch.__all__))\n"
    )
    assert out == "True"
    on_disk = {p.parent.name for p in (ROOT / "skillchain_torch").glob("*/__init__.py")}
    assert on_disk | {"envs", "trainers"} == set(SUBPACKAGES)
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    shipped = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert {f"skillchain_torch.{n}" for n in SUBPACKAGES} <= set(shipped["packages"])


def test_license_and_py_typed_ship():
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert pyproject["project"]["license"] == "MIT"  # an SPDX expression (PEP 639)
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "skillchain_torch developers" in text
    assert (ROOT / "skillchain_torch" / "py.typed").is_file()
    assert "py.typed" in pyproject["tool"]["setuptools"]["package-data"]["skillchain_torch"]
