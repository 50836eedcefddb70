"""The initial mesh: a user's mesh, the CPU dense path (visual hull, PatchMatch, Poisson), or
Gray-code structured light on projector rigs."""
