"""Capture -> mesh: RAW decode, poses, initial mesh, visibility, subdivision, joint
optimisation, export, relighting, evaluation."""
