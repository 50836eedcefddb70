"""User text (paths, names, notes, messages that embed them) as a terminal line should show it.

A name may hold anything a file system or a YAML string can: a newline would break a one-line
message in two, an escape sequence would restyle the terminal, a bidirectional override would
show the text reversed, and an undecodable byte (a surrogate in a ``Path``) cannot be encoded
at all. :func:`printable` writes each of those as its Python escape and leaves the rest as it
is:

>>> printable("a\\nb [/x] ñ")
'a\\\\nb [/x] ñ'
"""

from __future__ import annotations


def printable(value: object) -> str:
    """``str(value)`` with every character that is not printable (control and format
    characters, line and paragraph separators, lone surrogates) as its escape, e.g. ``\\n``."""
    text = str(value)
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
