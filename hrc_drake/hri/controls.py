"""Names of Meshcat controls (buttons, sliders) that survive the browser.

Drake's `Meshcat::AddButton` (and `AddSlider`) pastes the control's name into a JavaScript string
in single quotes that the page `eval`s, and dat.GUI, the page's control panel, shows the name as
HTML. So in Drake 1.51, tried in Chromium (`tests/test_browser.py`):
- an apostrophe or a line break ends the string: the page's `eval` fails and the control is never
  shown (`"F1: the robot's proposal"` is skipped, `"F2 instead"` beside it shows);
- a backslash starts an escape: the control shows, but its clicks come back under another name
  and never count;
- `<`, `>` and `&` are read as HTML: the label shown is not the name.
Every name sent to Meshcat's controls goes through `control_name`, which keeps letters, digits,
spaces and a few plain signs, and `add_button` is the one way the project adds a button. (Scene
paths, e.g. those MeshcatVisualizer builds from model instance names, travel as msgpack data
and are split, never evaluated, by the page: only control names need this.)
"""

from __future__ import annotations

from pydrake.geometry import Meshcat

# Signs a control name may hold besides letters, digits and spaces: none of them means anything
# inside a JavaScript string in single quotes, a template or HTML text.
SAFE_SIGNS = frozenset("-_.,:;()+=/#!?@%*|~[]^")
_QUOTES = frozenset("'\"`\u2018\u2019\u201a\u201b\u201c\u201d\u00b4")


def control_name(text: str) -> str:
    """`text` made safe as the name of a Meshcat control (see the module docstring): quotes are
    dropped ("robot's" -> "robots"), a backslash becomes "/", any other sign outside
    `SAFE_SIGNS` and any line break becomes a space; spaces are collapsed. ValueError if
    nothing is left."""
    kept = []
    for char in text:
        if char in _QUOTES:
            continue
        if char == "\\":
            kept.append("/")
        elif char.isalnum() or char in SAFE_SIGNS:
            kept.append(char)
        else:
            kept.append(" ")
    name = " ".join("".join(kept).split())
    if not name:
        raise ValueError(f"control name {text!r} has nothing left once made safe for Meshcat")
    return name


def is_safe_control_name(name: str) -> bool:
    """Whether `name` is already what `control_name` makes of it."""
    try:
        return control_name(name) == name
    except ValueError:
        return False


def add_button(meshcat: Meshcat, text: str) -> str:
    """Add a button labelled `control_name(text)` to `meshcat`'s control panel; returns the
    name to read its clicks by (`meshcat.GetButtonClicks(name)`)."""
    name = control_name(text)
    meshcat.AddButton(name)
    return name


__all__ = ["SAFE_SIGNS", "add_button", "control_name", "is_safe_control_name"]
