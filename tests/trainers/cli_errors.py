"""How the command-line hardening tests run ``skillchain`` and read its one error line.

Each reproducer of issue 17 C runs the installed console script once (:func:`run_cli`); its
variants call ``main`` in-process (:func:`main_refused`), which prints the same line.

Example:
    >>> error_line("usage: skillchain train [-h]\\nskillchain train: error: --runs must be >= 1")
    'skillchain train: error: --runs must be >= 1'
"""

import subprocess
import sys
from pathlib import Path

import pytest

from skillchain_torch.trainers.config.cli import main

SCRIPT = Path(sys.executable).parent / "skillchain"
TINY = ["--map", "pinball_box", "--runs", "1", "--episodes", "1", "--max-episode-steps", "50",
        "--quiet"]


def run_cli(*argv, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([str(SCRIPT), *map(str, argv)], capture_output=True, text=True,
                          timeout=300, cwd=cwd)  # fmt: skip


def error_line(stderr: str, command: str = "train") -> str:
    assert "Traceback" not in stderr, stderr
    lines = [line for line in stderr.splitlines() if ": error:" in line]
    assert len(lines) == 1, stderr
    assert lines[0].startswith(f"skillchain {command}: error: "), stderr
    assert stderr.strip().splitlines()[-1] == lines[0], stderr  # the message ends the output
    return lines[0]


def refused(done: subprocess.CompletedProcess, *fragments, command: str = "train") -> str:
    assert done.returncode == 2, (done.returncode, done.stderr)
    line = error_line(done.stderr, command)
    for fragment in fragments:
        assert fragment in line, line
    return line


def main_refused(capsys, argv, *fragments, command: str = "train") -> str:
    with pytest.raises(SystemExit) as info:
        main([str(a) for a in argv])
    assert info.value.code == 2
    line = error_line(capsys.readouterr().err, command)
    for fragment in fragments:
        assert fragment in line, line
    return line
