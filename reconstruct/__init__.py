"""Capture -> mesh: RAW decode, poses, initial mesh, visibility, subdivision, joint
optimisation, export, relighting, evaluation."""

import os

# The compiled kernels (numba, OpenMP threading layer) run many short parallel regions with
# serial NumPy work between them; GNU OpenMP's default keeps idle threads spinning for a while
# after each region, which burned ~15 % of the optimiser's CPU time for no wall-clock gain
# (bench/README.md, issue 14). Passive waiting must be chosen before OpenMP starts, hence here;
# a value the user set wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
