"""The end effector's Cartesian impedance model (thesis §3.1), and the free point-mass plant it renders."""

from coassist.model.impedance import ImpedanceModel, continuous_matrices, discretize
from coassist.model.plant import PointMassPlant, plant_step

__all__ = ["ImpedanceModel", "PointMassPlant", "continuous_matrices", "discretize", "plant_step"]
