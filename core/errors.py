"""The one error type users see.

It lives in ``calibration`` because that is the package every other package may import
(``calibration`` imports none of them), so drivers, reconstruction and the CLI all raise and
catch the same class. The CLI prints ``str(error)`` as one line and exits non-zero.
"""

from __future__ import annotations


class RigError(Exception):
    """A problem the user can fix: says what went wrong (naming the file, key, device or frame)
    and how to fix it."""

    def __init__(self, problem: str, fix: str | None = None) -> None:
        self.problem = problem
        self.fix = fix
        super().__init__(f"{problem} — {fix}" if fix else problem)


class MissingDependencyError(RigError):
    """An optional package or system library needed for a device is not installed."""

    def __init__(self, package: str, extra: str | None = None, why: str = "") -> None:
        from core.install import install_command  # only when raised: keeps start-up light

        install = install_command(extra) if extra else f"pip install {package}"
        super().__init__(
            f"{package} is not installed{': ' + why if why else ''}", f"install it with `{install}`"
        )
