"""The shared floor of spectral-rig: the one error type, YAML that people write, the session
format (layout, manifest, typed ``session.yaml``), frame labels and config parsing.

Every other package may import it; it imports none of them.
"""
