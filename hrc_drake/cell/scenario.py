"""Scenarios in the cell layer: what a scenario builds (the plant and scene graph configs, the
motion options, the cell design).

The schema is `hrc_drake.scenario.schema.Scenario` (Drake-free, shared with the task layer). It
is loaded as Drake's `hardware_sim` loads its scenarios: the file, then the command line's
`--scenario-text` layered on the result, so a misspelt key or a value of the wrong type fails
loudly either way; the loader is `hrc_drake.scenario.load`, held to Drake's `yaml_load_typed`
by a test.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

from pydrake.geometry import DefaultProximityProperties, SceneGraphConfig
from pydrake.multibody.plant import MultibodyPlantConfig

from hrc_drake.cell_models import CellDesign
from hrc_drake.motion.options import MotionOptions
from hrc_drake.scenario.load import load_scenario
from hrc_drake.scenario.schema import Scenario
from hrc_drake.tasks.assembly import AssemblySpec

# `--lean`: the same models, physics and limits, with 0.5 s bolting holds (tests, previews).
LEAN = "{motion: {hold_time: 0.5}, run: {settle_time: 0.2}}"
DEFAULT_SCENARIO = "row1-optimal"


def load_cell_scenario(
    name_or_path: str | Path | None = None, scenario_text: str | Sequence[str] | None = None
) -> Scenario:
    """A scenario file (a path, or a name under scenarios/) with YAML overrides on top (one text,
    or several applied in turn); with no file, the overrides apply to the defaults.

    Loaded once and checked once, by the project's one loader
    (`hrc_drake.scenario.load.load_scenario`): strict in the way of Drake's `yaml_load_typed`
    (which `tests/test_scenario_loader.py` holds it to, scenario by scenario), Drake-free so
    that the task layer reads the same files, and with errors of one line that name the file
    (or `--scenario-text`), the key and the type it expects, or the line and column of a YAML
    syntax error."""
    return load_scenario(name_or_path, scenario_text)


def plant_config(scenario: Scenario) -> MultibodyPlantConfig:
    """The MultibodyPlantConfig of the scenario's `physics` section."""
    physics = scenario.physics
    return MultibodyPlantConfig(
        time_step=physics.time_step,
        contact_model=physics.contact_model,
        discrete_contact_approximation=physics.discrete_contact_approximation,
        contact_surface_representation=physics.contact_surface_representation,
    )


def scene_graph_config(scenario: Scenario) -> SceneGraphConfig:
    """The SceneGraphConfig of the scenario's `physics.contact`: the contact material of every
    geometry whose model does not set its own, compliant unless the model says rigid."""
    contact = scenario.physics.contact
    return SceneGraphConfig(
        default_proximity_properties=DefaultProximityProperties(
            compliance_type="compliant",
            hydroelastic_modulus=contact.hydroelastic_modulus,
            resolution_hint=contact.resolution_hint,
            margin=contact.margin,
            hunt_crossley_dissipation=contact.hunt_crossley_dissipation,
            relaxation_time=contact.relaxation_time,
            static_friction=contact.static_friction,
            dynamic_friction=contact.dynamic_friction,
        )
    )


def motion_options(scenario: Scenario) -> MotionOptions:
    """The motion layer's options with the scenario's `motion` section applied."""
    return dataclasses.replace(MotionOptions(), **dataclasses.asdict(scenario.motion))


def cell_design(scenario: Scenario, spec: AssemblySpec) -> CellDesign:
    """The cell for `spec`: the scenario's `cell` layout, else the spec's `cell:` section."""
    return CellDesign.of(spec, scenario.cell)
