"""Figures 8 and 9 of the paper: the state graph and the learning curve (matplotlib, headless)."""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from hrc_drake.atomic import atomic_write_bytes
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.learn import LearningResult

_COLOURS = {
    StateKind.START: "#4caf50",
    StateKind.NORMAL: "#d0d7e2",
    StateKind.TERMINAL: "#e53935",
    StateKind.WRONG: "#ffb300",
    StateKind.DEAD_END: "#9e9e9e",
}


FORMATS = (".png", ".pdf", ".svg")
"""File suffixes the figures can be written as (matplotlib picks the backend by format)."""


def save_figure(fig, path: str | Path, dpi: int = 120) -> None:
    """Write `fig` to `path` (.png, .pdf or .svg) atomically, with the same bytes for the same
    figure; closes the figure. ValueError naming the formats for another suffix."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        plt.close(fig)
        raise ValueError(f"{path}: figures are written as {', '.join(FORMATS)}, not {suffix!r}")
    # No creation date and fixed SVG ids (salted by a constant, not at random): the same figure
    # gives the same bytes in every format.
    metadata = {".pdf": {"CreationDate": None}, ".svg": {"Date": None}}.get(suffix)
    buffer = io.BytesIO()
    with matplotlib.rc_context({"svg.hashsalt": "hrc_drake"}):
        fig.savefig(buffer, format=suffix[1:], dpi=dpi, bbox_inches="tight", metadata=metadata)
    plt.close(fig)
    atomic_write_bytes(Path(path), buffer.getvalue())


def plot_state_graph(space: StateSpace, path: str | Path) -> None:
    """Figure 8: states by depth, start green, terminals red, wrong amber, dead ends grey."""
    graph = space.to_networkx()
    by_depth: dict[int, list] = {}
    for node, data in graph.nodes(data=True):
        by_depth.setdefault(data["depth"], []).append(node)
    pos = {}
    for depth, nodes in by_depth.items():
        nodes.sort(key=lambda n: graph.nodes[n]["id"])
        for i, node in enumerate(nodes):
            pos[node] = (depth * 3.0, -(i - (len(nodes) - 1) / 2))
    fig, ax = plt.subplots(figsize=(11, 7))
    for u, v, data in graph.edges(data=True):
        (x0, y0), (x1, y1) = pos[u], pos[v]
        bend = 0.12  # same sign both ways: an edge and its undo bow apart
        ax.annotate(
            "",
            xy=(x1, y1),
            xytext=(x0, y0),
            arrowprops={
                "arrowstyle": "->",
                "color": "#90a4ae" if data["undo"] else "#37474f",
                "linestyle": "--" if data["undo"] else "-",
                "shrinkA": 14,
                "shrinkB": 14,
                "connectionstyle": f"arc3,rad={bend}",
            },
        )
        if not data["undo"]:
            ax.text(
                (x0 + x1) / 2,
                (y0 + y1) / 2 + 0.12,
                data["task"],
                fontsize=7,
                ha="center",
                color="#37474f",
            )
    for node, data in graph.nodes(data=True):
        kind = StateKind(space.kind[data["id"]])
        x, y = pos[node]
        ax.scatter(
            [x],
            [y],
            s=700,
            color=_COLOURS[kind],
            edgecolors="black",
            zorder=3,
            marker="X" if kind == StateKind.WRONG else "o",
        )
        ax.text(x, y, data["name"], ha="center", va="center", fontsize=9, zorder=4)
    handles = [
        plt.Line2D([], [], marker="o", linestyle="", color=c, markersize=10, label=k.label)
        for k, c in _COLOURS.items()
    ]
    ax.legend(handles=handles, loc="lower left", fontsize=8)
    ax.set_title(f"{space.spec.name}: {space.n_states} states (dashed: undo)")
    ax.axis("off")
    save_figure(fig, path)


def plot_learning_curve(result: LearningResult, path: str | Path, window: int = 20) -> None:
    """Figure 9: return per episode and its `window`-episode moving average."""
    fig, ax = plt.subplots(figsize=(9, 4.5))
    episodes = range(1, result.episodes + 1)
    ax.plot(episodes, result.returns, color="#bdbdbd", linewidth=0.8, label="return")
    ax.plot(
        episodes,
        result.moving_average(window),
        color="#424242",
        linewidth=2,
        label=f"{window}-episode average",
    )
    ax.set_xlabel("episode")
    ax.set_ylabel("return")
    ax.set_title(
        f"Q-learning, {result.schedule} schedule, seed {result.seed}: {result.episodes} episodes"
    )
    ax.legend()
    save_figure(fig, path)
