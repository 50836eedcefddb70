"""Mesh geometry stages: visibility V(i) and √3 subdivision to the resolvable density."""
