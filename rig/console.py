"""The console every command prints through.

What a command prints holds user text (paths, profile, device and store entry names, notes,
messages that embed them), so nothing printed is read as rich markup or emoji codes, nor
highlighted: ``[/x]`` in a path prints as itself instead of failing, ``[gphoto2]`` is not
eaten. Every string is also shown by :func:`core.text.printable`, so a name holding a newline
or an escape sequence stays on its line. Styles are given with ``style=`` or a ``Text``.
"""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.text import Text, TextType

from core.text import printable


class PlainConsole(Console):
    """A rich console that takes every string as plain, printable text."""

    def __init__(self, **options: Any) -> None:
        super().__init__(**{"markup": False, "emoji": False, "highlight": False, **options})

    def render_str(self, text: str, **options: Any) -> Text:
        """Each string printed, a table's cells and title included, comes through here."""
        return super().render_str(printable(text), **options)

    def input(self, prompt: TextType = "", *, markup: bool = False, emoji: bool = False,
              password: bool = False, stream: Any = None) -> str:
        """A prompt is plain text too (rich's own default reads it as markup)."""
        return super().input(prompt, markup=markup, emoji=emoji, password=password,
                             stream=stream)


def console(*, stderr: bool = False, **options: Any) -> Console:
    """A :class:`PlainConsole` on stdout, or stderr; ``options`` as rich's ``Console`` takes."""
    return PlainConsole(stderr=stderr, **options)
