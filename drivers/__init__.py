"""Devices: one Protocol per kind, transports, real drivers, and the simulated rig."""
