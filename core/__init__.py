"""The shared floor of spectral-rig: the one error type, YAML that people write, the session
format (layout, manifest, typed ``session.yaml``), frame labels, config parsing, the session
lock and the process's stop signals.

Every other package may import it; it imports none of them.
"""
