"""Joint optimisation of vertex positions, spectral reflectance and light positions
(Spectral MVIR, paper eq. 1): cost and exact Jacobians, LM + PCG solver, the paper's steps."""

from reconstruct.optimise.cost import JointCost
from reconstruct.optimise.linearisation import Linearisation
from reconstruct.optimise.problem import Frames, Observations, Problem, Rig, Weights
from reconstruct.optimise.problem_setup import build_problem
from reconstruct.optimise.settings import OptimiseInput, OptimiseSettings
from reconstruct.optimise.solver import SolverSettings, levenberg_marquardt
from reconstruct.optimise.steps import OptimiseResult, optimise

__all__ = [
    "Frames",
    "JointCost",
    "Linearisation",
    "Observations",
    "OptimiseInput",
    "OptimiseResult",
    "OptimiseSettings",
    "Problem",
    "Rig",
    "SolverSettings",
    "Weights",
    "build_problem",
    "levenberg_marquardt",
    "optimise",
]
