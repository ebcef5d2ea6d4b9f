"""Every file and every `hrc_drake` name the docs write in backticks exists: a path
(`hrc_drake/cell/run/run.py`, `models/`, `docs/spec.md`) is a file or folder of the
repository, and a dotted name (`hrc_drake.cell.run.run.run_scenario`) is a module, or a name
in one, that imports. (Read from README.md and docs/*.md; run as the docs' reader would.)"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
# A path: under a known top folder, a file with its extension or a folder with its slash (a
# name such as `examples/hardware_sim`, Drake's, or a Gym id is not a path of ours).
TOPS = ("hrc_drake/", "models/", "docs/", "tests/", "benchmarks/", "scenarios/", "examples/",
        "tools/")  # fmt: skip
PATH = re.compile(rf"^(?:{'|'.join(re.escape(t) for t in TOPS)})[\w./-]*(?:\.\w+|/)$")
DOTTED = re.compile(r"^hrc_drake(?:\.\w+)+$")


def _backticked(doc: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", doc.read_text(), flags=re.S)  # code blocks are examples
    return re.findall(r"`([^`\n]+)`", text)


def _resolves(dotted: str) -> bool:
    """A module, or an attribute chain from the longest module prefix that imports."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for name in parts[cut:]:
            if not hasattr(obj, name):
                return False
            obj = getattr(obj, name)
        return True
    return False


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_the_files_and_names_a_doc_names_exist(doc):
    missing = []
    for token in _backticked(doc):
        token = token.rstrip(".,:;")
        if (PATH.match(token) and not (REPO / token).exists()) or (
            DOTTED.match(token) and not _resolves(token)
        ):
            missing.append(token)
    assert missing == [], f"{doc.name} names what does not exist: {missing}"


def test_the_check_sees_names():
    """The docs do name files and symbols (the test above has something to check)."""
    tokens = [t for doc in DOCS for t in _backticked(doc)]
    assert sum(bool(PATH.match(t)) for t in tokens) > 20
    assert sum(bool(DOTTED.match(t)) for t in tokens) > 5


# A row of docs/testing.md's benchmark table: | `script` | what | `command` | report |.
BENCH_ROW = re.compile(r"^\| `(benchmarks/bench_\w+\.py)` \|([^|]*)\| `([^`]*)` \|([^|]*)\|$", re.M)


def test_every_benchmark_is_listed_with_its_command_and_report():
    """docs/testing.md lists every `benchmarks/bench_*.py`, each row with what it measures, a
    command that runs that script and the report it writes; it lists no script that is gone."""
    rows = BENCH_ROW.findall((REPO / "docs" / "testing.md").read_text())
    listed = {script for script, *_ in rows}
    shipped = {f"benchmarks/{p.name}" for p in (REPO / "benchmarks").glob("bench_*.py")}
    assert sorted(shipped - listed) == [], "not in docs/testing.md's table: add a row for each"
    assert sorted(listed - shipped) == [], "docs/testing.md lists scripts that are gone: drop them"
    bad = [
        script
        for script, what, command, report in rows
        if not what.strip() or not command.startswith(f"python {script}") or ".md" not in report
    ]
    assert bad == [], f"rows without what, a command running the script, or a report: {bad}"
