"""Grasp/place poses, inverse kinematics, collision-free trajectories, plan validation."""
