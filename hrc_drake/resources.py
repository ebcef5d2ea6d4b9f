"""Where the project's data lives: the models package, assembly specs and scenarios.

The models are found through `models/package.xml` (package name `hrc_drake_models`), so model
files and directives refer to each other by `package://hrc_drake_models/...` URIs.
"""

from __future__ import annotations

import os
from pathlib import Path

MODELS_PACKAGE = "hrc_drake_models"
_REPO_ROOT = Path(__file__).resolve().parent.parent


def _data_dir(env_var: str, default: Path, what: str) -> Path:
    path = Path(os.environ.get(env_var, default))
    if not path.is_dir():
        raise FileNotFoundError(
            f"{what} folder not found at {path}. hrc_drake reads its data from the source tree: "
            f"install it editable (pip install -e .) from a checkout, or set {env_var}."
        )
    return path


def models_dir() -> Path:
    """The folder holding `package.xml` and every model file."""
    return _data_dir("HRC_DRAKE_MODELS", _REPO_ROOT / "models", "models")


def scenarios_dir() -> Path:
    """The folder holding the scenario files (operator scripts, Table 2 rows)."""
    return _data_dir("HRC_DRAKE_SCENARIOS", _REPO_ROOT / "scenarios", "scenarios")


def default_assembly() -> Path:
    """The flange case of the paper, as an assembly spec."""
    return models_dir() / "assemblies" / "flange.yaml"


def package_uri(relative: str) -> str:
    """A `package://` URI for a file under `models/`."""
    return f"package://{MODELS_PACKAGE}/{relative}"
