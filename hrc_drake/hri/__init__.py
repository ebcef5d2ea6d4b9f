"""The operator side of the human-robot interface: scripted, stochastic, following."""
