"""Compiled (numba) loops of the joint cost and its solver, one module per job: frame
sampling and projection, the rendering residuals, the Gauss–Newton normal equations, the
normals, the block preconditioner and CG's vector updates. Each kernel is a top-level function
so numba's on-disk cache (``cache=True``) can store it."""
