"""Assembly specs, state graphs, MDP, exact and learned policies. Imports no Drake."""
