"""The agent kernels give the same bits whichever CPU runs them.

setup.py builds the agent kernels twice over (``NATIVE_CLONES`` in backends/native_maths.h:
AVX2 and plain x86-64, picked when the module loads). Here the same sources are compiled again with
``-DSKILLCHAIN_NO_CLONES`` (plain x86-64 only), swapped in, and short skill-chaining and flat
runs must leave checkpoints identical to those of the installed build, which on an AVX2
machine is the AVX2 code.
"""

from __future__ import annotations

import ast
import importlib.util
import platform
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest
import torch

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.backends import hierarchical, initiation
from skillchain_torch.backends import sarsa as native_sarsa
from skillchain_torch.options import OptionBank
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

ROOT = Path(__file__).resolve().parents[2]
KERNELS = {  # module holding the compiled handle -> its source
    initiation: "skillchain_torch/backends/_initiation.c",
    hierarchical: "skillchain_torch/backends/_hierarchical.c",
    native_sarsa: "skillchain_torch/backends/_sarsa.c",
}
COMPILER = shutil.which(sysconfig.get_config_var("CC").split()[0] if sysconfig.get_config_var(
    "CC") else "cc")  # fmt: skip

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        not (sys.platform.startswith("linux") and platform.machine() == "x86_64"
             and COMPILER and all(m._c is not None for m in KERNELS)),
        reason="the clones are built on x86-64 Linux with GCC, and this needs a compiler"),
]


def build_plain(tmp_path: Path) -> dict:
    """The kernels compiled without clones, loaded under their own names."""
    flags = ast.literal_eval((ROOT / "setup.py").read_text().split("FLAGS = ")[1].split("\n")[0])
    include = sysconfig.get_paths()["include"]
    modules = {}
    for holder, source in KERNELS.items():
        name = Path(source).stem
        target = tmp_path / f"{name}{sysconfig.get_config_var('EXT_SUFFIX')}"
        subprocess.run([COMPILER, "-shared", "-fPIC", *flags, "-DSKILLCHAIN_NO_CLONES",
                        f"-I{include}", f"-I{ROOT / 'skillchain_torch' / 'backends'}",
                        str(ROOT / source), "-o", str(target), "-lm"], check=True)  # fmt: skip
        spec = importlib.util.spec_from_file_location(name, target)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        modules[holder] = module
    return modules


def run_both() -> list[dict]:
    """Checkpoint-like states of a short skill-chaining run and a short flat run."""
    states = []
    config = TrainConfig(agent="skill-chaining", map="pinball_box", runs=3, seed=2, episodes=6,
                         max_episode_steps=300, slots=4)  # fmt: skip
    trainer = PopulationTrainer(config)
    trainer.agent = SkillChainingAgent(OptionBank.build(3, 4, seed=2), order=4, alpha=0.001,
                                       seed=2, gestation=2)  # fmt: skip
    assert trainer.agent.native
    trainer.train()
    states.append(trainer.agent.state_dict())
    flat = PopulationTrainer(TrainConfig(map="pinball_box", runs=3, seed=2, episodes=4,
                                         max_episode_steps=300))  # fmt: skip
    flat.train()
    states.append({"weight": flat.weights.clone(), "returns": torch.as_tensor(flat.returns)})
    return states


def flatten(state, prefix=""):
    if isinstance(state, dict):
        for key, value in state.items():
            yield from flatten(value, f"{prefix}.{key}")
    elif isinstance(state, torch.Tensor):
        yield prefix, state


def test_plain_build_gives_the_installed_builds_bits(tmp_path, monkeypatch):
    installed = run_both()
    for holder, module in build_plain(tmp_path).items():
        monkeypatch.setattr(holder, "_c", module)
    plain = run_both()
    options = installed[0]["bank"]["classifier.sweeps_done"]
    assert int(options.sum()) > 0  # initiation sets were fitted
    for a, b in zip(installed, plain):
        a, b = dict(flatten(a)), dict(flatten(b))
        assert a.keys() == b.keys()
        for name in a:
            assert torch.equal(a[name], b[name]), name
