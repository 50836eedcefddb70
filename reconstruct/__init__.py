"""Capture -> mesh: RAW decode, poses, initial mesh, visibility, subdivision, joint
optimisation, export, relighting, evaluation."""

import os

# The compiled kernels run many short OpenMP regions with serial NumPy work between them, and
# GNU OpenMP's idle threads would spin between them for no wall-clock gain. Passive waiting must
# be chosen before OpenMP starts, hence here; a value the user set wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
