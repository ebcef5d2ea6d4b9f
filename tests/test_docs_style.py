"""The docs read as a reference should: short paragraphs, an opening that says what a page is
for with a command to try, and every scenario key listed with its meaning and default.

- Paragraphs: in README.md and docs/*.md, no prose paragraph and no list item is longer than
  `MAX_LINES` lines (code blocks, tables, headings and images are not prose). A list item is
  counted as a paragraph of its own, so a long paragraph cannot pass by becoming one bullet.
- Openings: each docs/*.md opens, right under its title, with a sentence of prose (what the
  reader can do with the page), and within `OPENING_LINES` lines of the title shows at least one
  command: a code span or a code block naming `hrc-drake`, `python` or `bash`. A page that is
  pure reference (docs/conventions.md) is no exception: it opens with the command that shows
  what it defines (`hrc-drake states` lists the task tokens), so every page can be tried.
- Scenario keys: every field of `Scenario`, recursively through the nested dataclasses (the
  members of a union such as the drivers' and the faults' tagged entries, and the `sensors:`
  mapping's preset and per-port keys) is a row of a `| key | default | meaning |` table in
  the docs, with a meaning, and the default the row states is the dataclass's.
"""

from __future__ import annotations

import dataclasses
import math
import re
import typing
from pathlib import Path

import pytest
import yaml

from hrc_drake.scenario.schema import DRAKE_SECTIONS, Scenario
from hrc_drake.scenario.sensors import CAMERA, REALISTIC, SensorSettings

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
DRAKE_SECTION = object()  # the default of a Drake section's own row: its rows state theirs
KEY_DOC = "scenario.md"  # the page of the scenario's keys (README links to it)
MAX_LINES = 10
OPENING_LINES = 15

# A dataclass used by several sibling fields is listed once, under a placeholder, after a row
# for each sibling (`sensors.ur3`, ..., then `sensors.<port>.rate`).
PLACEHOLDERS = {SensorSettings: "<port>"}

LIST_ITEM = re.compile(r"^\s*(?:[-*+]|\d+[.)])\s")
COMMAND = re.compile(r"\b(?:hrc-drake|python|bash)\b")


def _blocks(text: str) -> list[tuple[int, int]]:
    """The prose paragraphs and list items of a markdown text, as (first line, line count)."""
    blocks: list[list[int]] = []
    current: list[int] | None = None  # [first line, count]
    fence = False
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if stripped.startswith("```"):
            fence, current = not fence, None
            continue
        if fence or not stripped or stripped.startswith(("|", "#", "![", "<")):
            current = None
            continue
        # A list item starts a block; so does a line after a blank one (an indented paragraph
        # inside a list item is a block of its own, as it reads).
        if LIST_ITEM.match(line) or current is None:
            current = [number, 0]
            blocks.append(current)
        current[1] += 1
    return [(first, count) for first, count in blocks]


def _long_paragraphs(doc: Path) -> list[str]:
    return [
        f"line {first}: {count} lines"
        for first, count in _blocks(doc.read_text())
        if count > MAX_LINES
    ]


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_no_paragraph_is_longer_than_ten_lines(doc):
    long = _long_paragraphs(doc)
    assert long == [], f"{doc.name}: split these paragraphs (at most {MAX_LINES} lines): {long}"


def _opening_problem(doc: Path) -> str:
    """What is wrong with the page's opening, or "" if nothing."""
    lines = doc.read_text().splitlines()
    if not lines or not lines[0].startswith("# "):
        return "the first line is not a title (# ...)"
    body = lines[1 : 1 + OPENING_LINES]
    first = next((line for line in body if line.strip()), "")
    if first.lstrip().startswith(("#", "```", "|", "![", "<", "-", "*")):
        return f"the title is followed by {first.strip()[:30]!r}, not a sentence on what to do"
    text = "\n".join(body)
    spans = re.findall(r"`([^`\n]+)`", re.sub(r"```.*?(?:```|\Z)", "", text, flags=re.S))
    if any(COMMAND.search(span) for span in spans):
        return ""
    # A code block opened within the opening lines counts by its language or its first lines.
    for match in re.finditer(r"^```(\w*)\n", text, flags=re.M):
        after = "\n".join(lines[1:])[match.end() :].split("```", 1)[0]
        if match.group(1) == "bash" or COMMAND.search(after):
            return ""
    return f"no command (hrc-drake, python or bash) in its first {OPENING_LINES} lines"


DOC_PAGES = [doc for doc in DOCS if doc.parent.name == "docs"]


@pytest.mark.parametrize("doc", DOC_PAGES, ids=lambda p: p.name)
def test_each_page_opens_with_what_to_do_and_a_command(doc):
    problem = _opening_problem(doc)
    assert problem == "", f"{doc.name}: {problem}"


def test_the_checks_see_what_they_check(tmp_path):
    """The paragraph and opening checks fail on text that breaks them."""
    prose = "# T\n\n" + "word\n" * 11 + "\n- item\n" + "  more\n" * 11 + "\n```\n" + "x\n" * 20
    assert _blocks(prose) == [(3, 11), (15, 12)]
    page = tmp_path / "page.md"
    page.write_text("# T\n\nWhat it is for.\n" + "\nmore\n" * 8 + "`hrc-drake states`\n")
    assert "no command" in _opening_problem(page)  # the command comes too late
    page.write_text("# T\n\n## Section\n\nRun `hrc-drake states`.\n")
    assert "not a sentence" in _opening_problem(page)
    page.write_text("# T\n\nList the states:\n\n```bash\nhrc-drake states\n```\n")
    assert _opening_problem(page) == ""


def _dataclasses_in(tp) -> list[type]:
    """The dataclasses a field's type names: itself, or the members of its union/list."""
    if dataclasses.is_dataclass(tp):
        return [tp]
    return [cls for arg in typing.get_args(tp) for cls in _dataclasses_in(arg)]


def _field_default(f: dataclasses.Field):
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def scenario_keys(cls: type = Scenario, prefix: str = "") -> dict[str, object]:
    """Every key of a scenario, dotted from the top (`run.period`), with its default.

    A union with several dataclass members that hold fields (the faults' tagged entries) names
    the member: `faults[!GripLost].force`; a dataclass shared by sibling fields is listed once
    under its placeholder (`sensors.<port>.rate`)."""
    hints = typing.get_type_hints(cls)
    # A field the loader fills (`metadata={"yaml": False}`) is no key of the file.
    fields = [f for f in dataclasses.fields(cls) if f.metadata.get("yaml", True)]
    types = [tuple(_dataclasses_in(hints[f.name])) for f in fields]
    keys: dict[str, object] = {}
    done: set[type] = set()
    for f, members in zip(fields, types, strict=True):
        key = prefix + f.name
        keys[key] = _field_default(f)
        with_fields = [m for m in members if dataclasses.fields(m)]
        for member in with_fields:
            shared = member in PLACEHOLDERS and sum(member in t for t in types) > 1
            if shared and member in done:
                continue
            done.add(member)
            name = prefix + PLACEHOLDERS[member] if shared else key
            tag = f"[!{member.__name__}]" if len(with_fields) > 1 else ""
            keys.update(scenario_keys(member, f"{name}{tag}."))
    return keys


def drake_keys() -> dict[str, object]:
    """The scenario's Drake sections (`DRAKE_SECTIONS`, read as Drake's own config types), and
    within them every key whose cell default differs from Drake's own, with that default."""
    from pydrake.geometry import SceneGraphConfig
    from pydrake.multibody.plant import MultibodyPlantConfig

    from hrc_drake.cell.scenario import CellConfigs

    cell = CellConfigs()
    keys: dict[str, object] = dict.fromkeys(DRAKE_SECTIONS, DRAKE_SECTION)

    def differing(ours, theirs, prefix: str) -> None:
        for name in (f.name for f in type(ours).__fields__):
            mine, drakes = getattr(ours, name), getattr(theirs, name)
            if hasattr(type(mine), "__fields__"):
                differing(mine, drakes, f"{prefix}{name}.")
            elif mine != drakes:
                keys[prefix + name] = mine

    differing(cell.plant_config, MultibodyPlantConfig(), "plant_config.")
    differing(cell.scene_graph_config, SceneGraphConfig(), "scene_graph_config.")
    keys["lcm_buses.default.lcm_url"] = cell.lcm_buses["default"].lcm_url
    return keys


def _key_rows() -> dict[str, tuple[str, str, str]]:
    """The rows of every `| key | default | meaning |` table in the docs, by key."""
    rows: dict[str, tuple[str, str, str]] = {}
    for doc in DOCS:
        in_table = False
        for line in doc.read_text().splitlines():
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if [c.lower() for c in cells] == ["key", "default", "meaning"]:
                in_table = True
                continue
            if not line.startswith("|"):
                in_table = False
            if in_table and len(cells) == 3 and not set(cells[0]) <= {"-", ":"}:
                key = cells[0].strip("`")
                assert key not in rows, f"{doc.name}: key {key} is listed twice"
                rows[key] = (doc.name, cells[1], cells[2])
    return rows


def _same(stated, actual) -> bool:
    if isinstance(actual, bool) or isinstance(stated, bool):
        return stated is actual
    if isinstance(actual, int | float) and isinstance(stated, int | float):
        return math.isclose(stated, actual, rel_tol=1e-9, abs_tol=1e-12)
    if isinstance(actual, list | tuple) and isinstance(stated, list):
        return len(stated) == len(actual) and all(map(_same, stated, actual))
    return stated == actual


def test_every_scenario_key_is_listed_with_its_meaning_and_default():
    keys = scenario_keys() | drake_keys()
    rows = _key_rows()
    missing = [key for key in keys if key not in rows]
    assert missing == [], f"scenario keys missing from the docs' key tables: {missing}"
    # Other pages' key tables (docs/spec.md's, of a spec's `cell:`) list other files' keys.
    unknown = [key for key, row in rows.items() if row[0] == KEY_DOC and key not in keys]
    assert unknown == [], f"{KEY_DOC} lists keys the scenario does not have: {unknown}"
    wrong = []
    for key, default in keys.items():
        doc, stated, meaning = rows[key]
        if len(meaning.split()) < 2:
            wrong.append(f"{doc} {key}: no meaning")
        listed = isinstance(default, list) and all(map(dataclasses.is_dataclass, default))
        if dataclasses.is_dataclass(default) or default is DRAKE_SECTION or (listed and default):
            continue  # a section (or a list of them): its rows below state its defaults
        text = stated.strip("`")
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text
        if not _same(value, default):
            wrong.append(f"{doc} {key}: default {stated}, the schema's is {default!r}")
    assert wrong == [], "; ".join(wrong)


def test_the_key_walk_reaches_every_kind_of_section():
    """Nested sections, union members, tagged list entries and the shared per-port keys."""
    keys = scenario_keys()
    for key in ("station.rg2.grip_force", "drivers.ur3.host", "faults[!Pushed].torque",
                "sensors.<port>.latency", "sensors.wrench", "cell.bins.holds",
                "interaction.delay.median", "safety.function.unlock_delay"):  # fmt: skip
        assert key in keys
    assert "sensors.ur3.latency" not in keys


def test_the_realistic_figures_in_the_docs_are_the_presets():
    """docs/scenario.md's table of the `realistic` preset and the camera states their figures
    (the first number of each cell; 0 for a figure the model leaves at 0)."""
    models = {**REALISTIC, "camera": CAMERA}
    columns = ("rate", "latency", "max_latency", "noise", "rate_noise", "quantum", "dropout")
    seen, wrong = set(), []
    for line in (REPO / "docs" / KEY_DOC).read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        port = cells[0].strip("`")
        if port not in models or len(cells) != 1 + len(columns):
            continue
        seen.add(port)
        for name, cell in zip(columns, cells[1:], strict=True):
            stated = float(re.match(r"[-+\d.e]+", cell).group())
            actual = getattr(models[port], name)
            if not math.isclose(stated, actual, abs_tol=1e-12):
                wrong.append(f"{port}.{name}: {cell}, the preset's is {actual}")
        angle = re.search(r"angle ([\d.e-]+)", cells[4])
        if models[port].angle_noise or angle:
            assert angle and float(angle.group(1)) == models[port].angle_noise, port
    assert seen == set(models), f"ports missing from {KEY_DOC}'s figures: {set(models) - seen}"
    assert wrong == [], "; ".join(wrong)
