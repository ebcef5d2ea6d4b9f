"""Generated assemblies of growing size: the flange case on a wider base with more flanges."""

from __future__ import annotations

from pathlib import Path

import yaml

from hrc_drake.tasks.assembly import AssemblySpec
from hrc_drake.tasks.spec import parse_spec

MODELS = Path(__file__).resolve().parent.parent / "models"


def generated_spec(slots: int, ovals: int, squares: int = 1) -> AssemblySpec:
    """`ovals` oval flanges (one on each square, the rest on the base), `squares` squares."""
    data = generated_data(slots, ovals, squares)
    return parse_spec(data, source=data["name"])


def generated_data(slots: int, ovals: int, squares: int = 1) -> dict:
    """The spec of `generated_spec` as YAML data."""
    return {
        "name": f"generated-{slots}slots-{ovals}F-{squares}S",
        "base": {"slots": slots},
        "parts": {
            "F": {"count": ovals, "footprint": 1},
            "S": {"count": squares, "footprint": 2, "host": {"tag": "0"}},
        },
        "mounts": [
            {"part": "F", "to": "base", "count": ovals - squares},
            {"part": "F", "to": "S", "count": squares},
            {"part": "S", "to": "base", "count": squares},
        ],
        "precedence": {"complete_first": ["S"]},
        "goal": {"min_gap": [{"parts": ["F", "F"], "slots": 2}]},
        "mistakes": [{"part": "F", "to": "S"}],
    }


# (slots, oval flanges, square flanges): from 20 to over a million states.
SIZES = [(3, 2, 1), (5, 3, 1), (7, 4, 1), (9, 5, 1), (10, 5, 2), (11, 5, 2)]


def two_host_spec(slots: int, on_base: int) -> AssemblySpec:
    """Two host flanges (S, tag 0; T, tag 1), one oval flange on each and `on_base` more on
    the base: ``on_base + 4`` parts. (8, 2) is six parts on eight slots (29,267 states), (10, 3)
    seven parts on ten slots (820,427 states)."""
    data = two_host_data(slots, on_base)
    return parse_spec(data, source=data["name"])


def two_host_data(slots: int, on_base: int) -> dict:
    """The spec of `two_host_spec` as YAML data."""
    return {
        "name": f"two-host-{slots}slots-{on_base + 2}F",
        "base": {"slots": slots},
        "parts": {
            "F": {"name": "oval flange", "count": on_base + 2, "footprint": 1},
            "S": {"name": "square flange", "count": 1, "footprint": 2, "host": {"tag": "0"}},
            "T": {"name": "second square flange", "count": 1, "footprint": 2, "host": {"tag": "1"}},
        },
        "mounts": [
            {"part": "F", "to": "S", "count": 1},
            {"part": "F", "to": "T", "count": 1},
            {"part": "S", "to": "base", "count": 1},
            {"part": "T", "to": "base", "count": 1},
            *([{"part": "F", "to": "base", "count": on_base}] if on_base else []),
        ],
        "precedence": {"complete_first": ["S", "T"]},
        "goal": {"min_gap": [{"parts": ["F", "F"], "slots": 2}]},
        "mistakes": [{"part": "F", "to": "S"}, {"part": "F", "to": "T"}],
    }


def _shipped(name: str) -> dict:
    return yaml.safe_load((MODELS / "assemblies" / f"{name}.yaml").read_text())


# Learning at scale (benchmarks/bench_coverage.py): name -> spec data, 20 to 820,427 states.
LEARNING_SIZES = {
    "flange (shipped)": lambda: _shipped("flange"),
    "three-oval (shipped)": lambda: _shipped("three-oval"),
    "two-host, 5 slots, 3 F": lambda: two_host_data(5, 1),
    "one host, 7 slots, 4 F": lambda: generated_data(7, 4, 1),
    "two-host, 7 slots, 4 F": lambda: two_host_data(7, 2),
    "two squares, 8 slots, 4 F": lambda: generated_data(8, 4, 2),
    "two-host, 8 slots, 4 F (six parts)": lambda: two_host_data(8, 2),
    "one host, 9 slots, 5 F": lambda: generated_data(9, 5, 1),
    "two-host, 9 slots, 5 F": lambda: two_host_data(9, 3),
    "two squares, 10 slots, 5 F": lambda: generated_data(10, 5, 2),
    "two-host, 10 slots, 5 F (seven parts)": lambda: two_host_data(10, 3),
}
