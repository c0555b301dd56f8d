"""``skillchain reproduce paper`` and ``skillchain verify`` on a tiny study (issue 15)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest


def skillchain(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "skillchain_torch.trainers.cli", *args],
                          capture_output=True, text=True, cwd=cwd, timeout=600)  # fmt: skip


@pytest.mark.slow
def test_reproduce_resumes_and_its_runs_verify(tmp_path):
    out = tmp_path / "paper"
    args = ("reproduce", "paper", "--out", str(out), "--runs", "2", "--episodes", "3",
            "--instances", "simple", "--quiet")  # fmt: skip
    first = skillchain(*args)
    assert first.returncode == 0, first.stderr
    for agent in ("flat", "skill-chaining", "given-options"):
        run = out / "simple" / agent
        assert np.load(run / "returns.npy").shape == (2, 3)
        assert json.loads((run / "config.json").read_text())["seed"] == 1000
        assert "commit" in json.loads((run / "run_info.json").read_text())
    assert (out / "README.md").read_text().count("| claim |") == 1
    assert (out / "fig4a.png").is_file()
    stamp = (out / "simple" / "flat" / "run_info.json").stat().st_mtime
    again = skillchain(*args)  # every run is done: nothing is trained again
    assert again.returncode == 0, again.stderr
    assert (out / "simple" / "flat" / "run_info.json").stat().st_mtime == stamp
    for agent in ("skill-chaining", "given-options"):
        check = skillchain("verify", str(out / "simple" / agent), "--agents", "1")
        assert check.returncode == 0 and "match (1 of 1" in check.stdout, check.stdout
    # banks are too big to publish: without one, the skill-chaining agent is re-run to rebuild it
    (out / "simple" / "skill-chaining" / "options.pt").unlink()
    rebuilt = skillchain("verify", str(out / "simple" / "given-options"), "--agents", "1")
    assert rebuilt.returncode == 0 and "match (1 of 1" in rebuilt.stdout, rebuilt.stdout
    assert (out / "simple" / "skill-chaining" / "verify-options" / "agent1.pt").is_file()
    returns = np.load(out / "simple" / "flat" / "returns.npy")
    returns[1, 2] += 1.0
    np.save(out / "simple" / "flat" / "returns.npy", returns)
    bad = skillchain("verify", str(out / "simple" / "flat"), "--agents", "1")
    assert bad.returncode == 1 and "MISMATCH" in bad.stdout
    outside = skillchain("verify", str(out / "simple" / "flat"), "--agents", "5")
    assert outside.returncode == 2 and "agent 5 is not in" in outside.stderr
