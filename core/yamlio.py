"""Reading YAML that people write (profiles, configs, camera files, session.yaml, index.yaml).

PyYAML's ``safe_load`` keeps the last of two equal keys, so a profile with ``radius_m`` twice
silently uses one of them. :class:`UniqueKeyLoader` rejects duplicates, and :func:`read_yaml`
turns every way a file can be unreadable (missing, a folder, binary, bad syntax, a duplicate
key) into one :class:`RigError` line naming the file and the line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from yaml.constructor import ConstructorError
from yaml.nodes import MappingNode

from core.errors import RigError

MERGE_TAG = "tag:yaml.org,2002:merge"


class UniqueKeyLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that raises a ``ConstructorError`` on a repeated mapping key."""

    def construct_mapping(self, node: MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == MERGE_TAG:  # `<<:` merges may be overridden on purpose
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.get(key)
            except TypeError:  # unhashable key: the base class reports it
                continue
            if first is not None:
                raise ConstructorError(
                    "while constructing a mapping",
                    node.start_mark,
                    f"found duplicate key {key!r} (first at line {first})",
                    key_node.start_mark,
                )
            seen[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep)


def load_yaml(text: str) -> Any:
    """Parse YAML text with duplicate keys rejected (raises ``yaml.YAMLError``)."""
    return yaml.load(text, Loader=UniqueKeyLoader)


def yaml_problem(error: yaml.YAMLError) -> str:
    """A YAML error as one line: the problem and where (PyYAML's own text spans lines)."""
    if isinstance(error, yaml.MarkedYAMLError):
        mark = error.problem_mark or error.context_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        return f"{error.problem or error.context}{where}"
    return " ".join(str(error).split())


def read_yaml(path: Path, what: str, fix: str) -> Any:
    """The parsed content of a YAML file ``what`` (e.g. "profile"), or a RigError naming the
    file and the line, with ``fix`` as the fix for syntax errors."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError as error:
        raise RigError(f"{what} {path} does not exist", "give an existing file") from error
    except IsADirectoryError as error:
        raise RigError(f"{what} {path} is a folder", "give the path of a YAML file") from error
    except UnicodeDecodeError as error:
        raise RigError(
            f"{what} {path} is not UTF-8 text (byte {error.start}: binary file?)",
            "give a YAML text file",
        ) from error
    except OSError as error:
        raise RigError(f"cannot read {what} {path}: {error.strerror}", "check the path") from error
    try:
        return load_yaml(text)
    except yaml.YAMLError as error:
        raise RigError(f"{what} {path} is not valid YAML: {yaml_problem(error)}", fix) from error
