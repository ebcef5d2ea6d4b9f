"""The Drake cell, in four rooms and three shared modules (read `docs/architecture.md` first):

- `station/`: the simulated cell (`make_cell_station`): the plant of the UR3, the gripper, the
  plate and the parts; the configuration sensor, the simulated operator and body, the desk
  script, the faults.
- `controller/`: what a real cell would run (`make_controller`): the Supervisor, its recovery,
  anticipation and keep-clear, the separation monitor, the forecast of the operator's body.
- `link/`: the station and the controller in two processes, over LCM.
- `run/`: the closed loop of a scenario, its runs, recordings and evaluations.
- `ports.py` (the values on the ports between station and controller), `person.py` (the
  person model both sides share) and `scenario.py` (a scenario loaded by Drake's YAML loader,
  and what it builds).

`controller/` imports nothing from `station/` and `station/` nothing from `controller/`
(`tests/test_import_cycles.py`).
"""
