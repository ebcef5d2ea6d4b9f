"""Scenarios in the cell layer: Drake's typed YAML loader, and what a scenario builds.

The schema is `hrc_drake.hri.scenario.Scenario` (Drake-free, shared with the task layer). Here it
is loaded as Drake's `hardware_sim` loads its scenarios: `yaml_load_typed` on the file, then on
the command line's `--scenario-text` with the file's values as defaults, so a misspelt key or a
value of the wrong type fails loudly either way.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

from pydrake.common.yaml import yaml_load_typed
from pydrake.multibody.plant import MultibodyPlantConfig

from hrc_drake.cell_models import CellDesign
from hrc_drake.hri.scenario import Scenario, ScenarioError, check_scenario, scenario_file
from hrc_drake.motion.options import MotionOptions
from hrc_drake.tasks.spec import AssemblySpec

# `--lean`: the same models, physics and limits, with 0.5 s bolting holds (tests, previews).
LEAN = "{motion: {hold_time: 0.5}, run: {settle_time: 0.2}}"


def load_cell_scenario(
    name_or_path: str | Path | None = None, scenario_text: str | Sequence[str] | None = None
) -> Scenario:
    """A scenario file (a path, or a name under scenarios/) with YAML overrides on top (one text,
    or several applied in turn).

    With no file, the overrides apply to the defaults. ScenarioError names the file (or
    `--scenario-text`) and the key for an unknown key or a value of the wrong type."""
    scenario, source = Scenario(), "<defaults>"
    if name_or_path is not None:
        path = scenario_file(name_or_path)
        source = str(path)
        try:
            scenario = yaml_load_typed(schema=Scenario, filename=str(path), defaults=Scenario())
        except RuntimeError as err:
            raise ScenarioError(f"scenario {path}: {err}") from err
        if not scenario.name:
            scenario.name = path.stem
    texts = [scenario_text] if isinstance(scenario_text, str) else list(scenario_text or ())
    if texts:
        source = f"{source} with --scenario-text"
    for text in texts:
        try:
            scenario = yaml_load_typed(schema=Scenario, data=text, defaults=scenario)
        except RuntimeError as err:
            raise ScenarioError(f"--scenario-text: {err}") from err
    return check_scenario(scenario, source)


def plant_config(scenario: Scenario) -> MultibodyPlantConfig:
    """The MultibodyPlantConfig of the scenario's `physics` section."""
    physics = scenario.physics
    return MultibodyPlantConfig(
        time_step=physics.time_step,
        contact_model=physics.contact_model,
        discrete_contact_approximation=physics.discrete_contact_approximation,
        contact_surface_representation=physics.contact_surface_representation,
    )


def motion_options(scenario: Scenario) -> MotionOptions:
    """The motion layer's options with the scenario's `motion` section applied."""
    return dataclasses.replace(MotionOptions(), **dataclasses.asdict(scenario.motion))


def cell_design(scenario: Scenario, spec: AssemblySpec) -> CellDesign:
    """The cell for `spec`: the scenario's `cell` layout, else the spec's `cell:` section."""
    return CellDesign.of(spec, scenario.cell)
