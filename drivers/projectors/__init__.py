"""Projector drivers and the patterns they show."""
