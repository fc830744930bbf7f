"""The robot model: robot files, parameters by name, CasADi kinematics, inverse
kinematics, transforms, the pinocchio reference and the example robots."""
