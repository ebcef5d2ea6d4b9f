"""The project's one scenario loader (`hrc_drake.scenario.load`, Drake-free) reads every
scenario as Drake's `yaml_load_typed` does, with command-line text layered on the file as
`hardware_sim` layers its `--scenario_text`: the run loads a scenario once, with it."""

import dataclasses

import pytest
from pydrake.common.yaml import yaml_load_typed

from hrc_drake.cell.scenario import LEAN
from hrc_drake.resources import scenarios_dir
from hrc_drake.scenario.load import load_scenario
from hrc_drake.scenario.schema import Scenario

CATALOGUE = sorted(p.stem for p in scenarios_dir().glob("*.yaml"))
TEXTS = [
    LEAN,
    "{run: {max_steps: 12}, safety: {separation: predictive}}",
    "{station: {rg2: {grip_force: 25}, ur3: {tracking_tolerance: 0.1}}, run: {period: 0.04}}",
]


def _drake(name: str, texts: list[str]) -> Scenario:
    path = scenarios_dir() / f"{name}.yaml"
    scenario = yaml_load_typed(schema=Scenario, filename=str(path), defaults=Scenario())
    scenario.name = scenario.name or path.stem
    for text in texts:
        scenario = yaml_load_typed(schema=Scenario, data=text, defaults=scenario)
    return scenario


def test_the_catalogue_is_not_empty():
    assert len(CATALOGUE) >= 10


@pytest.mark.parametrize("name", CATALOGUE)
def test_every_catalogue_scenario_loads_as_drake_loads_it(name):
    ours = load_scenario(name)
    assert dataclasses.asdict(ours) == dataclasses.asdict(_drake(name, []))


@pytest.mark.parametrize("text", TEXTS)
def test_scenario_text_layers_on_the_file_as_drake_layers_it(text):
    for name in ("row1-optimal", "shared-desk"):
        ours = load_scenario(name, [text])
        theirs = _drake(name, [text])
        assert dataclasses.asdict(ours) == dataclasses.asdict(theirs), (name, text)
        # The text changed something, and both loaders kept the file's other values.
        assert dataclasses.asdict(ours) != dataclasses.asdict(load_scenario(name))
