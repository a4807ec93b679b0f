"""The robot: URDF → serial chain and limits, its kinematics, the state layout."""
