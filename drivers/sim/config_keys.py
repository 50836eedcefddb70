"""One check for every section of the sim's config: a misspelt key is an error, not ignored."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from core.errors import RigError


def reject_unknown_keys(data: Mapping[str, Any], known: Iterable[str], where: str) -> None:
    """Raise a :class:`RigError` naming the section and the allowed keys if ``data`` has others."""
    allowed = set(known)
    unknown = set(data) - allowed
    if unknown:
        raise RigError(
            f"{where}: unknown key(s) {', '.join(sorted(unknown))}",
            f"use only {', '.join(sorted(allowed))}",
        )
