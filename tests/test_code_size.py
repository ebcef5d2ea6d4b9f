"""Size limits a maintainer can hold the package to: no module of `hrc_drake` over 600 lines,
no function over 60 (a longer one is split into named steps, as the coverage learner's rounds
are). The source is read, not imported."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "hrc_drake"
MODULE_LINES = 600
FUNCTION_LINES = 60


def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def test_the_package_has_modules_to_check():
    assert len(_modules()) > 100


def test_no_module_is_over_600_lines():
    long = {
        str(p.relative_to(PACKAGE)): n
        for p in _modules()
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MODULE_LINES
    }
    assert long == {}, f"modules over {MODULE_LINES} lines: {long}; split them"


def long_functions(source: str) -> dict[str, int]:
    """The functions (and methods) of `source` over FUNCTION_LINES lines, by name and line."""
    found = {}
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            lines = node.end_lineno - node.lineno + 1
            if lines > FUNCTION_LINES:
                found[f"{node.name} (line {node.lineno})"] = lines
    return found


def test_no_function_is_over_60_lines():
    long = {}
    for path in _modules():
        for name, lines in long_functions(path.read_text(encoding="utf-8")).items():
            long[f"{path.relative_to(PACKAGE)}: {name}"] = lines
    assert long == {}, f"functions over {FUNCTION_LINES} lines: {long}; split them"


def test_the_function_check_counts_a_long_function():
    body = "\n".join(f"    x{i} = {i}" for i in range(FUNCTION_LINES))
    assert long_functions(f"def short():\n    pass\n\ndef long():\n{body}\n") == {
        "long (line 4)": FUNCTION_LINES + 1
    }
