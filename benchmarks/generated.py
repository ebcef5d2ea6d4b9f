"""Generated assemblies of growing size: the flange case on a wider base with more flanges."""

from __future__ import annotations

from hrc_drake.tasks.assembly import AssemblySpec
from hrc_drake.tasks.spec import parse_spec


def generated_spec(slots: int, ovals: int, squares: int = 1) -> AssemblySpec:
    """`ovals` oval flanges (one on each square, the rest on the base), `squares` squares."""
    data = {
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
    return parse_spec(data, source=data["name"])


# (slots, oval flanges, square flanges): from 20 to over a million states.
SIZES = [(3, 2, 1), (5, 3, 1), (7, 4, 1), (9, 5, 1), (10, 5, 2), (11, 5, 2)]
