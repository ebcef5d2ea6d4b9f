"""The scenario's Drake sections (`plant_config`, `scene_graph_config`, `simulator_config`,
`cameras`, `lcm_buses`) are Drake's own config types, read by Drake's `yaml_load_typed` and
layered as `hardware_sim` layers them; the Drake-free layers never read them."""

import subprocess
import sys

import numpy as np
import pytest
from pydrake.common.yaml import yaml_load_typed
from pydrake.systems.analysis import ExtractSimulatorConfig

from hrc_drake.cell.scenario import (
    CellConfigs,
    cell_configs,
    contact_material,
    lcm_url,
    load_cell_scenario,
    plant_step,
)
from hrc_drake.cell.station import make_cell_station, simulate_station, station_scenario
from hrc_drake.scenario.schema import ScenarioError

FILE = """
name: drake-sections
plant_config: {time_step: 0.005}
scene_graph_config:
  default_proximity_properties: {static_friction: 0.8, dynamic_friction: 0.7}
lcm_buses: {default: {lcm_url: "udpm://239.241.129.92:20999?ttl=0"}}
"""
TEXTS = [
    "{plant_config: {time_step: 0.002}, simulator_config: {publish_every_time_step: true}}",
    "{scene_graph_config: {default_proximity_properties: {dynamic_friction: 0.6}}}",
]


@pytest.fixture
def scenario_file(tmp_path):
    path = tmp_path / "drake-sections.yaml"
    path.write_text(FILE)
    return path


def test_the_sections_layer_as_drakes_own_loader_layers_them(scenario_file):
    ours = cell_configs(load_cell_scenario(scenario_file, TEXTS))
    theirs = CellConfigs()
    # hardware_sim's layering: the file, then each text, each onto the result.
    theirs = yaml_load_typed(schema=CellConfigs, filename=str(scenario_file), defaults=theirs,
                             allow_yaml_with_no_schema=True)  # fmt: skip
    for text in TEXTS:
        theirs = yaml_load_typed(schema=CellConfigs, data=text, defaults=theirs)
    assert repr(ours) == repr(theirs)
    # Each layer changed what it gave and kept the rest.
    assert ours.plant_config.time_step == 0.002
    assert ours.plant_config.discrete_contact_approximation == "sap"  # the cell's default
    material = ours.scene_graph_config.default_proximity_properties
    assert (material.static_friction, material.dynamic_friction) == (0.8, 0.6)
    assert material.hydroelastic_modulus == 5.0e6  # the cell's default, not Drake's 1e7
    assert ours.simulator_config.publish_every_time_step


def test_the_task_layer_reads_a_scenario_with_drake_sections_without_drake(scenario_file):
    code = (
        "import sys\n"
        "from hrc_drake.scenario.load import load_scenario\n"
        f"s = load_scenario({str(scenario_file)!r}, {TEXTS!r})\n"
        "print(s.name, len(s.drake), any(m.startswith('pydrake') for m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["drake-sections", "6", "False"]  # one per section given


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{plant_config: {time_stp: 0.01}}", r"--scenario-text: plant_config: .*time_stp"),
        ("{plant_config: {time_step: .inf}}",
         r"plant_config.time_step: inf is not a number the cell"),
        ("{plant_config: {time_step: 0}}", r"plant_config.time_step: .* give > 0"),
        ("{plant_config: {discrete_contact_approximation: tamsi}}", "SAP-family"),
        ("{plant_config: {contact_model: springs}}", r"plant_config: Unknown contact_model"),
        ("{simulator_config: {integration_scheme: magic}}", "simulator_config: Unknown"),
        ("{scene_graph_config: {default_proximity_properties: {static_friction: 0.1}}}",
         r"static_friction: must be >= dynamic_friction"),
        ("{cameras: [{name: c, width: 0}]}", r"cameras\[0\]: Invalid camera"),
        ("{lcm_buses: {default: {url: x}}}", r"lcm_buses: .*url.*DrakeLcmParams"),
        ("{plant_config: {time_step: 0.01, time_step: 0.02}}", "duplicate key 'time_step'"),
    ],
)  # fmt: skip
def test_what_drake_or_the_cell_refuses_is_one_line_naming_the_section(text, message):
    with pytest.raises(ScenarioError, match=message) as err:
        load_cell_scenario(None, text)
    assert "\n" not in str(err.value)


def test_the_plant_step_contact_material_and_bus_come_from_the_sections(scenario_file):
    scenario = load_cell_scenario(scenario_file)
    assert plant_step(scenario) == 0.005
    assert contact_material(scenario).static_friction == 0.8
    assert lcm_url(scenario) == "udpm://239.241.129.92:20999?ttl=0"
    with pytest.raises(ScenarioError, match="no bus 'arm'"):
        lcm_url(scenario, "arm")


def test_the_station_applies_the_simulator_config_and_builds_the_cameras():
    text = (
        "{simulator_config: {publish_every_time_step: true}, cameras: [{name: top, width: 64, "
        "height: 48, renderer_class: RenderEngineVtk, X_PB: {translation: [0.2, 0.0, 1.0], "
        "rotation: !Rpy {deg: [180, 0, 90]}}}]}"
    )
    scenario = station_scenario(load_cell_scenario(None, text), robot=False)
    station = make_cell_station(scenario)
    simulator = simulate_station(station, duration=0.01)
    assert ExtractSimulatorConfig(simulator).publish_every_time_step
    image = station.diagram.GetOutputPort("sim.camera.rgb_image").Eval(simulator.get_context())
    pixels = np.array(image.data, copy=True)
    assert pixels.shape[:2] == (48, 64) and pixels[..., :3].std() > 0  # it rendered the cell
    # No camera in the scenario and none asked for: no port (and no renderer to set up).
    plain = make_cell_station(station_scenario(load_cell_scenario(None), robot=False))
    assert not plain.diagram.HasOutputPort("sim.camera.rgb_image")
