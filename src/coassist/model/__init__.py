"""The end effector's Cartesian impedance model (thesis §3.1)."""

from coassist.model.impedance import ImpedanceModel, continuous_matrices, discretize

__all__ = ["ImpedanceModel", "continuous_matrices", "discretize"]
