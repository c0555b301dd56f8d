"""The option tree as a figure (the paper's Figure 2): ``option_tree.png`` beside
``option_tree.json``.

Each panel is one agent's tree. The base events (the goal; the discs of ``--subgoals random``)
sit on the top row; an option hangs below what it targets: a base event, or the option whose
initiation set it chains to (section 4.3). A node is an option: ``o<slot>``, its executions'
success rate over the run and their count; filled where its set is learned, pale where it is
still learning, dashed while it gestates. The panels show the agents with the most options
(deepest first), at most ``panels`` of them.

Example:
    >>> import matplotlib; matplotlib.use("Agg")
    >>> tree = {"slots": 4, "base_events": ["goal"], "agents": [{"agent": 0, "options": [
    ...     {"slot": 0, "parent": -1, "target": "goal", "status": "LEARNED", "depth": 1,
    ...      "successes": 8, "timeouts": 2, "episode_ends": 0},
    ...     {"slot": 1, "parent": 0, "target": "slot 0", "status": "LEARNING", "depth": 2,
    ...      "successes": 1, "timeouts": 3, "episode_ends": 0}]}]}
    >>> fig = plot_option_tree(tree)
    >>> len(fig.axes)
    1
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["plot_option_tree", "save_option_tree", "tree_layout"]

_FACE = {"LEARNED": "#4c72b0", "LEARNING": "#c6d4ea", "GESTATING": "white"}


def tree_layout(options: list[dict], base_events: list[str]) -> dict:
    """``{node: (x, depth)}`` for the base events (``"event:<name>"``, depth 0) and the options
    (their slot, depth from their parents): leaves take consecutive x, a parent sits over the
    middle of its children."""
    children: dict = {}
    slots = {o["slot"] for o in options}
    for o in options:
        parent = o["parent"]
        key = parent if parent >= 0 and parent in slots else f"event:{o['target']}"
        children.setdefault(key, []).append(o["slot"])
    roots = [f"event:{name}" for name in base_events if f"event:{name}" in children]
    roots = roots or [f"event:{name}" for name in base_events[:1]]
    position: dict = {}
    next_x = [0.0]

    def place(node, depth: int) -> float:
        kids = sorted(children.get(node, []))
        if not kids:
            x = next_x[0]
            next_x[0] += 1.0
        else:
            xs = [place(k, depth + 1) for k in kids]
            x = (xs[0] + xs[-1]) / 2.0
        position[node] = (x, depth)
        return x

    for root in roots:
        place(root, 0)
    return position


def plot_option_tree(tree: dict, panels: int = 4):
    """The figure of ``tree`` (:func:`~.discovery_log.option_tree`'s dict)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    agents = sorted(tree["agents"], key=lambda a: (-max((o["depth"] for o in a["options"]),
                                                        default=0), -len(a["options"]),
                                                   a["agent"]))[:panels]  # fmt: skip
    agents = agents or tree["agents"][:1]
    cols = min(2, max(1, len(agents)))
    rows = -(-max(1, len(agents)) // cols)
    fig = Figure(figsize=(6.0 * cols, 3.8 * rows + 0.8))
    FigureCanvasAgg(fig)
    for i, agent in enumerate(agents):
        ax = fig.add_subplot(rows, cols, i + 1)
        _draw(ax, agent, tree["base_events"])
    fig.legend(handles=[Patch(facecolor=_FACE[s], edgecolor="black", label=label,
                              linestyle="--" if s == "GESTATING" else "-")
                        for s, label in (("LEARNED", "set learned"), ("LEARNING", "learning"),
                                         ("GESTATING", "gestating"))],
               loc="lower center", ncol=3, frameon=False)  # fmt: skip
    fig.suptitle("Option trees: each option hangs below its target; success rate of its "
                 "executions (count)", fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 0.95))
    return fig


def _draw(ax, agent: dict, base_events: list[str]) -> None:
    options = agent["options"]
    position = tree_layout(options, base_events)
    by_slot = {o["slot"]: o for o in options}
    for o in options:  # edges first, under the nodes
        parent = o["parent"]
        up = parent if parent in by_slot else f"event:{o['target']}"
        if up in position and o["slot"] in position:
            (x0, y0), (x1, y1) = position[up], position[o["slot"]]
            ax.plot([x0, x1], [-y0, -y1], color="0.5", lw=1, zorder=1)
    for node, (x, depth) in position.items():
        if isinstance(node, str):  # a base event
            ax.text(x, -depth, node.split(":", 1)[1], ha="center", va="center", fontsize=9,
                    bbox=dict(boxstyle="round", facecolor="#dd8452", edgecolor="black"),
                    zorder=2)  # fmt: skip
            continue
        o = by_slot[node]
        runs = sum(o.get(k, 0) for k in ("successes", "timeouts", "episode_ends"))
        rate = f"{100 * o['successes'] / runs:.0f}% ({runs})" if "successes" in o and runs \
            else "no runs"
        ax.text(x, -depth, f"o{node}\n{rate}", ha="center", va="center", fontsize=7,
                bbox=dict(boxstyle="round", facecolor=_FACE.get(o["status"], "white"),
                          edgecolor="black",
                          linestyle="--" if o["status"] == "GESTATING" else "-"),
                color="white" if o["status"] == "LEARNED" else "black", zorder=2)  # fmt: skip
    xs = [x for x, _ in position.values()] or [0.0]
    depths = [d for _, d in position.values()] or [0]
    ax.set_xlim(min(xs) - 0.8, max(xs) + 0.8)
    ax.set_ylim(-max(depths) - 0.7, 0.7)
    ax.set_title(f"agent {agent['agent']}: {len(options)} options, depth "
                 f"{max(depths)}", fontsize=9)  # fmt: skip
    ax.axis("off")


def save_option_tree(tree: dict, path: str | Path, panels: int = 4) -> Path:
    """Write :func:`plot_option_tree`'s figure to ``path``."""
    path = Path(path)
    plot_option_tree(tree, panels).savefig(path, dpi=110)
    return path
