"""The option tree's figure (issue 54, the paper's Figure 2) and each option's execution
counts in option_tree.json."""

from __future__ import annotations

import json

import numpy as np

from skillchain_torch.trainers.config.cli import main
from skillchain_torch.trainers.outputs.tree_figure import tree_layout


def test_layout_hangs_each_option_below_its_target():
    options = [{"slot": 0, "parent": -1, "target": "goal"},
               {"slot": 1, "parent": 0, "target": "slot 0"},
               {"slot": 2, "parent": 0, "target": "slot 0"},
               {"slot": 3, "parent": 1, "target": "slot 1"}]  # fmt: skip
    pos = tree_layout(options, ["goal"])
    assert pos["event:goal"][1] == 0 and pos[0][1] == 1 and pos[3][1] == 3
    assert pos[0][0] == (pos[1][0] + pos[2][0]) / 2  # a parent over its children's middle
    assert pos[3][0] == pos[1][0] and pos["event:goal"][0] == pos[0][0]


def test_a_run_writes_the_tree_figure_and_each_options_counts(tmp_path):
    out = tmp_path / "run"
    assert main(["train", "--agent", "skill-chaining", "--runs", "2", "--seed", "3",
                 "--episodes", "15", "--out", str(out),
                 "--quiet"]) == 0  # fmt: skip
    assert (out / "option_tree.png").stat().st_size > 0
    tree = json.loads((out / "option_tree.json").read_text())
    outcomes = np.load(out / "option_outcomes.npy")  # [P, E, 3] per agent-episode
    for agent in tree["agents"]:
        counts = np.array([[o["successes"], o["timeouts"], o["episode_ends"]]
                           for o in agent["options"]]).reshape(-1, 3)  # fmt: skip
        # every execution of the run is some option's, once
        assert np.array_equal(counts.sum(0), outcomes[agent["agent"]].sum(0))
    assert outcomes.sum() > 0
