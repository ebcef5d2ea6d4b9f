"""Scenarios: the schema of a run (`schema`), its checks (`check`) and its one loader (`load`),
Drake-free, which the task layer and the cell share."""
