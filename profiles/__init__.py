"""The rig profiles shipped with spectral-rig (YAML package data, named by file stem)."""

from importlib import resources


def shipped_profiles() -> list[str]:
    """Names of the profiles shipped here."""
    files = resources.files(__name__).iterdir()
    return sorted(p.name[:-5] for p in files if p.name.endswith(".yaml"))
