"""Scenarios: the schema of a run (`schema`), its checks (`check`) and its Drake-free loader
(`load`). The cell loads the same schema with Drake's `yaml_load_typed`
(`hrc_drake.cell.scenario`)."""
