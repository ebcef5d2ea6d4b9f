"""Scenarios in the cell layer: what a scenario builds (Drake's own configs of the plant, the
scene graph, the simulator, the cameras and the LCM buses; the motion options; the cell design).

The schema is `hrc_drake.scenario.schema.Scenario` (Drake-free, shared with the task layer),
read by the project's loader (`hrc_drake.scenario.load`). The sections that are Drake's own
config types (`DRAKE_SECTIONS`) are read here, by Drake's `yaml_load_typed`, as Drake's
`hardware_sim` reads its scenario: the file's, then each `--scenario-text`'s layered on the
result (`CellConfigs`). Drake's terse errors are wrapped into the project's one line naming the
source and the section.
"""

import copy
import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.schema import Transform
from pydrake.common.yaml import yaml_load_typed
from pydrake.geometry import DefaultProximityProperties, SceneGraphConfig
from pydrake.lcm import DrakeLcmParams
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import (
    ApplyMultibodyPlantConfig,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator, SimulatorConfig
from pydrake.systems.primitives import ConstantVectorSource
from pydrake.systems.sensors import CameraConfig

from hrc_drake.cell_models import CellDesign
from hrc_drake.motion.options import MotionOptions
from hrc_drake.scenario.load import load_scenario
from hrc_drake.scenario.schema import DrakeSection, Scenario, ScenarioError
from hrc_drake.tasks.assembly import AssemblySpec

# `--lean`: the same models, physics and limits, with 0.5 s bolting holds (tests, previews).
LEAN = "{motion: {hold_time: 0.5}, run: {settle_time: 0.2}}"
DEFAULT_SCENARIO = "row1-optimal"
# The default bus (`lcm_buses.default`): host-local multicast (ttl=0: the datagrams never leave
# this machine), on a port of its own so that another LCM user's default group
# (239.255.76.67:7667) does not mix in.
DEFAULT_LCM_URL = "udpm://239.241.129.92:20185?ttl=0"
# The station's bolts are locked joints, which only the SAP family of solvers supports.
SAP_FAMILY = ("sap", "similar", "lagged")


def _default_plant_config() -> MultibodyPlantConfig:
    # Calibrated (benchmarks/reports/contact.md, cell.md): with the contact material below (a
    # 1 ms relaxation time and Drake's 0.1 mm margin), 10 ms rests parts let go near their seats
    # within 0.12 s and the sensor reads every configuration, at twice the real-time factor of
    # 5 ms; `sap` rests the 67 g oval flange in its pocket where `lagged`/`similar` leave it
    # chattering (0.4 N of its 0.66 N weight carried, 9 mm/s left after 2 s, at 5 ms).
    return MultibodyPlantConfig(
        time_step=1e-2,
        contact_model="hydroelastic_with_fallback",
        discrete_contact_approximation="sap",
        contact_surface_representation="polygon",
    )


def _default_scene_graph_config() -> SceneGraphConfig:
    # The contact material of every collision geometry whose model does not set its own
    # (compliant: a part dropped a few mm onto a rigid seat is thrown out of it). The modulus
    # is half of Drake's default 1e7 Pa: at 1e7 and 10 ms a part pressed by the rigid fingers
    # onto a pocket's rim bursts out of the grasp (docs/station.md, "Contact settings"). The
    # margin is Drake's recommended 1e-4 m: a part let go on its seat does not fall into it for
    # a step. A 1 ms relaxation time (SAP's dissipation) rests a released part within a few
    # steps. Calibrated in benchmarks/reports/contact.md (`benchmarks/bench_contact.py`).
    return SceneGraphConfig(
        default_proximity_properties=DefaultProximityProperties(
            compliance_type="compliant",
            hydroelastic_modulus=5.0e6,
            resolution_hint=0.01,
            margin=1.0e-4,
            hunt_crossley_dissipation=10.0,
            relaxation_time=0.001,
            static_friction=0.6,
            dynamic_friction=0.5,
        )
    )


def _look_at(position, target) -> RigidTransform:
    # The camera frame of RgbdSensor: +z forward, +x right, +y down in the image.
    p, t = np.asarray(position, dtype=float), np.asarray(target, dtype=float)
    z = (t - p) / np.linalg.norm(t - p)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return RigidTransform(RotationMatrix(np.column_stack([x, y, z])), p)


# The still camera when a scenario names none: from the operator's side of the desk, looking
# at the plate (the README's pictures).
OPERATOR_VIEW = CameraConfig(
    name="operator_view",
    width=1024,
    height=640,
    focal=CameraConfig.FovDegrees(y=40.0),
    clipping_near=0.05,
    clipping_far=5.0,
    z_near=0.06,
    z_far=4.9,
    X_PB=Transform(_look_at([0.95, -0.75, 0.80], [0.17, -0.06, 0.14])),
    renderer_name="vtk",
    renderer_class="RenderEngineVtk",
)


@dataclass
class CellConfigs:
    """The scenario's Drake sections, as Drake's own types, with the cell's defaults.

    Attributes:
        plant_config: the MultibodyPlant's settings (`AddMultibodyPlant`).
        scene_graph_config: the default contact material (`default_proximity_properties`);
            its friction is given to every geometry but the gripper's fingers.
        simulator_config: applied to every simulator of the cell (`ApplySimulatorConfig`).
        cameras: the station's RGB cameras (stills); none given, `--still` adds the
            operator's view (`OPERATOR_VIEW`).
        lcm_buses: the LCM URL of each bus; `default` is the station's and the drivers' when
            `--lcm` is not given.
    """

    plant_config: MultibodyPlantConfig = field(default_factory=_default_plant_config)
    scene_graph_config: SceneGraphConfig = field(default_factory=_default_scene_graph_config)
    simulator_config: SimulatorConfig = field(default_factory=SimulatorConfig)
    cameras: list[CameraConfig] = field(default_factory=list)
    lcm_buses: dict[str, DrakeLcmParams] = field(
        default_factory=lambda: {"default": DrakeLcmParams(lcm_url=DEFAULT_LCM_URL)}
    )


def load_cell_scenario(
    name_or_path: str | Path | None = None, scenario_text: str | Sequence[str] | None = None
) -> Scenario:
    """A scenario file (a path, or a name under scenarios/) with YAML overrides on top (one text,
    or several applied in turn); with no file, the overrides apply to the defaults.

    Loaded once and checked once: the project's sections by `hrc_drake.scenario.load` (strict:
    one-line errors naming the file or `--scenario-text`, the key and the type it expects),
    and the Drake sections by Drake's loader (`cell_configs`), so that a problem in either is
    found before anything is built."""
    scenario = load_scenario(name_or_path, scenario_text)
    cell_configs(scenario)
    return scenario


def cell_configs(scenario: Scenario) -> CellConfigs:
    """The scenario's Drake sections read onto the cell's defaults (a copy: change it freely);
    ScenarioError, one line naming the source and the section, for what Drake refuses or
    the cell cannot build."""
    return copy.deepcopy(_read_configs(tuple(scenario.drake)))


@functools.lru_cache(maxsize=64)
def _read_configs(sections: tuple[DrakeSection, ...]) -> CellConfigs:
    configs = CellConfigs()
    for section in sections:
        try:
            configs = yaml_load_typed(schema=CellConfigs, data=section.text, defaults=configs)
        except (RuntimeError, ValueError, TypeError, AssertionError) as err:
            raise ScenarioError(_drake_error(section.source, section.key, err)) from None
        _check(configs, section.source, section.key)
    return configs


_KINDS = {
    "plant_config": "Drake's MultibodyPlantConfig",
    "scene_graph_config": "Drake's SceneGraphConfig",
    "simulator_config": "Drake's SimulatorConfig",
    "cameras": "a list of Drake's CameraConfig",
    "lcm_buses": "a mapping of bus names to Drake's DrakeLcmParams",
}


def _drake_error(source: str, key: str, err: Exception) -> str:
    detail = " ".join(str(err).split()) or type(err).__name__
    return (
        f"{source}: {key}: {detail[:200]}; give {_KINDS[key]} (docs/scenario.md, \"Drake's "
        'own configs")'
    )


def _check(configs: CellConfigs, source: str, key: str) -> None:
    """What Drake's types cannot say: values the cell cannot build with. Drake's own checks of
    names (contact model, integrator) run on throwaway objects, to fail at load, not mid-build."""

    def fail(where: str, message: str) -> ScenarioError:
        return ScenarioError(f"{source}: {where}: {message}")

    plant = configs.plant_config
    if key == "plant_config":
        if not plant.time_step > 0:
            raise fail("plant_config.time_step", "the cell is a discrete plant: give > 0 (1e-2)")
        if plant.discrete_contact_approximation not in SAP_FAMILY:
            raise fail(
                "plant_config.discrete_contact_approximation",
                f"{plant.discrete_contact_approximation!r}: the station's bolts (locked joints) "
                f"need a SAP-family one; use one of {', '.join(SAP_FAMILY)}",
            )
        _drake_accepts(
            lambda: ApplyMultibodyPlantConfig(plant, MultibodyPlant(plant.time_step)), fail, key
        )
    if key == "scene_graph_config":
        _check_contact(configs.scene_graph_config.default_proximity_properties, fail)
    if key == "cameras":
        for index, camera in enumerate(configs.cameras):
            if camera.renderer_class not in ("", "RenderEngineVtk"):
                raise fail(
                    f"cameras[{index}].renderer_class",
                    f"{camera.renderer_class!r}: the station renders with VTK; give "
                    "RenderEngineVtk or leave it out",
                )
            _drake_accepts(camera.MakeCameras, fail, f"cameras[{index}]")
    if key == "simulator_config":
        sim = Simulator(ConstantVectorSource([0.0]))
        _drake_accepts(lambda: ApplySimulatorConfig(configs.simulator_config, sim), fail, key)


def _drake_accepts(apply, fail, key: str) -> None:
    try:
        apply()
    except (RuntimeError, ValueError) as err:
        raise fail(key, " ".join(str(err).split())[:200]) from None


def _check_contact(props: DefaultProximityProperties, fail) -> None:
    where = "scene_graph_config.default_proximity_properties"
    for name in ("hydroelastic_modulus", "resolution_hint", "static_friction", "dynamic_friction"):
        if getattr(props, name) is None:
            raise fail(f"{where}.{name}", "the cell needs a value; give a number")
    for name in ("hydroelastic_modulus", "resolution_hint"):
        if not getattr(props, name) > 0:
            raise fail(f"{where}.{name}", "must be > 0")
    for name in ("margin", "relaxation_time", "hunt_crossley_dissipation", "dynamic_friction"):
        value = getattr(props, name)
        if value is not None and value < 0:
            raise fail(f"{where}.{name}", "must be >= 0")
    if props.static_friction < props.dynamic_friction:
        raise fail(f"{where}.static_friction", "must be >= dynamic_friction")


def plant_config(scenario: Scenario) -> MultibodyPlantConfig:
    """The scenario's MultibodyPlantConfig (`plant_config`, on the cell's defaults)."""
    return cell_configs(scenario).plant_config


def plant_step(scenario: Scenario) -> float:
    """The plant's discrete step [s]: the lockstep's exchange period."""
    return cell_configs(scenario).plant_config.time_step


def scene_graph_config(scenario: Scenario) -> SceneGraphConfig:
    """The scenario's SceneGraphConfig: the contact material of every geometry whose model
    does not set its own."""
    return cell_configs(scenario).scene_graph_config


def contact_material(scenario: Scenario) -> DefaultProximityProperties:
    """The default contact material (`scene_graph_config.default_proximity_properties`)."""
    return cell_configs(scenario).scene_graph_config.default_proximity_properties


def make_simulator(scenario: Scenario, diagram, context=None) -> Simulator:
    """A Simulator of `diagram` (from `context`, if given) with the scenario's
    `simulator_config` applied."""
    return configured_simulator(cell_configs(scenario).simulator_config, diagram, context)


def configured_simulator(config: SimulatorConfig | None, diagram, context=None) -> Simulator:
    """A Simulator of `diagram` (from `context`, if given) with `config` applied
    (`ApplySimulatorConfig`; None: Drake's defaults, which are `SimulatorConfig()`'s)."""
    simulator = Simulator(diagram) if context is None else Simulator(diagram, context)
    if config is not None:
        ApplySimulatorConfig(config, simulator)
    return simulator


def lcm_url(scenario: Scenario, bus: str = "default") -> str:
    """The LCM URL of `bus` in the scenario's `lcm_buses` (left empty: `DEFAULT_LCM_URL`);
    ScenarioError for a bus the scenario does not name."""
    buses = cell_configs(scenario).lcm_buses
    if bus not in buses:
        raise ScenarioError(
            f"lcm_buses: no bus {bus!r}; the scenario's buses are {sorted(buses)}; add "
            f"`lcm_buses: {{{bus}: {{lcm_url: ...}}}}`"
        )
    return buses[bus].lcm_url or DEFAULT_LCM_URL


def motion_options(scenario: Scenario) -> MotionOptions:
    """The motion layer's options with the scenario's `motion` section applied."""
    return dataclasses.replace(MotionOptions(), **dataclasses.asdict(scenario.motion))


def cell_design(scenario: Scenario, spec: AssemblySpec) -> CellDesign:
    """The cell for `spec`: the scenario's `cell` layout, else the spec's `cell:` section."""
    return CellDesign.of(spec, scenario.cell)
