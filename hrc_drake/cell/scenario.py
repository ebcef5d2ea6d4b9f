"""Scenarios in the cell layer: Drake's typed YAML loader, and what a scenario builds.

The schema is `hrc_drake.scenario.schema.Scenario` (Drake-free, shared with the task layer). Here it
is loaded as Drake's `hardware_sim` loads its scenarios: `yaml_load_typed` on the file, then on
the command line's `--scenario-text` with the file's values as defaults, so a misspelt key or a
value of the wrong type fails loudly either way.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

from pydrake.common.yaml import yaml_load_typed
from pydrake.geometry import DefaultProximityProperties, SceneGraphConfig
from pydrake.multibody.plant import MultibodyPlantConfig

from hrc_drake.cell_models import CellDesign
from hrc_drake.motion.options import MotionOptions
from hrc_drake.scenario.check import check_scenario
from hrc_drake.scenario.load import load_scenario, scenario_file
from hrc_drake.scenario.schema import Scenario, ScenarioError
from hrc_drake.tasks.assembly import AssemblySpec

# `--lean`: the same models, physics and limits, with 0.5 s bolting holds (tests, previews).
LEAN = "{motion: {hold_time: 0.5}, run: {settle_time: 0.2}}"
DEFAULT_SCENARIO = "row1-optimal"


def load_cell_scenario(
    name_or_path: str | Path | None = None, scenario_text: str | Sequence[str] | None = None
) -> Scenario:
    """A scenario file (a path, or a name under scenarios/) with YAML overrides on top (one text,
    or several applied in turn).

    With no file, the overrides apply to the defaults. The text is checked first by the strict
    loader of the task layer (`hrc_drake.scenario.load.load_scenario`), whose ScenarioError names
    the file (or `--scenario-text`), the key and the type it expects, or the line and column of a
    YAML syntax error; Drake's own errors are several lines of traceback about its conversion.
    Then Drake's `yaml_load_typed` loads it, as `hardware_sim` does."""
    checked = load_scenario(name_or_path, scenario_text)
    scenario, source = Scenario(), "<defaults>"
    if name_or_path is not None:
        path = scenario_file(name_or_path)
        source = str(path)
        scenario = _drake_load(f"scenario {path}", filename=str(path), defaults=Scenario())
        scenario.name = checked.name
    texts = [scenario_text] if isinstance(scenario_text, str) else list(scenario_text or ())
    if texts:
        source = f"{source} with --scenario-text"
    for text in texts:
        scenario = _drake_load("--scenario-text", data=text, defaults=scenario)
    return check_scenario(scenario, source)


def _drake_load(source: str, **kwargs) -> Scenario:
    try:
        return yaml_load_typed(schema=Scenario, **kwargs)
    except (RuntimeError, ValueError, TypeError) as err:
        # Not expected after the strict check; still one line, not the converter's traceback.
        last = str(err).strip().splitlines()[-1] if str(err).strip() else type(err).__name__
        raise ScenarioError(f"{source}: {last}") from None


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
