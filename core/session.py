"""The session directory (a public format, docs/architecture.md, Session format): its layout,
``session.yaml`` (:class:`core.session_info.SessionInfo`) and ``manifest.jsonl``
(:mod:`core.manifest`).

Capture writes it (``rig.capture``); reconstruction reads it. It lives here because
``reconstruct`` may not import ``rig``, and both need the same definition.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import yaml

from core.errors import RigError
from core.manifest import FrameRecord, read_manifest
from core.session_info import SessionInfo
from core.yamlio import load_yaml, yaml_problem

SESSION_FILE = "session.yaml"
RAW_DIR = "raw"
CALIBRATION_DIR = "calibration"
POSES_DIR = "poses"
RECON_DIR = "recon"
DEMO_SESSION_DIR = "session"  # where `rig demo --out FOLDER` puts its session


def find_session(path: Path) -> Path:
    """``path`` when it holds a session, else its ``session/`` folder when that does (the
    demo's output folder), else ``path`` unchanged (for the caller's error to name)."""
    path = Path(path)
    inner = path / DEMO_SESSION_DIR
    if not (path / SESSION_FILE).is_file() and (inner / SESSION_FILE).is_file():
        return inner
    return path


@dataclass
class Session:
    """A session directory opened for reading."""

    root: Path
    info: SessionInfo
    frames: list[FrameRecord]

    @classmethod
    def open(cls, root: Path, bound_views: bool = True) -> Session:
        """The session at ``root``; a manifest line naming a view beyond the plan is an error
        unless ``bound_views`` is False (`rig session verify` lists such lines instead)."""
        root = find_session(root)
        meta = root / SESSION_FILE
        if not meta.is_file():
            raise RigError(
                f"{root} is not a session directory (no {SESSION_FILE})",
                "give the folder that `rig capture --out` (or `rig demo --out`) created",
            )
        try:
            data = load_yaml(meta.read_text(encoding="utf-8"))
        except (yaml.YAMLError, UnicodeDecodeError) as exc:
            problem = yaml_problem(exc) if isinstance(exc, yaml.YAMLError) else "not UTF-8 text"
            raise RigError(
                f"{meta} is not valid YAML: {problem}", "fix the file (repeated keys, syntax)"
            ) from exc
        info = SessionInfo.from_mapping(data, str(meta))
        # sessions written by other tools may have no plan: then views are unbounded
        n_views = info.plan.views if bound_views else None
        return cls(root, info, read_manifest(root, n_views))

    @classmethod
    def of(cls, session: Session | Path) -> Session:
        """``session`` itself, or the session at that path opened (stages run alone)."""
        return session if isinstance(session, Session) else cls.open(session)

    @property
    def raw_dir(self) -> Path:
        return self.root / RAW_DIR

    @property
    def calibration_dir(self) -> Path:
        return self.root / CALIBRATION_DIR

    @property
    def poses_dir(self) -> Path:
        return self.root / POSES_DIR

    @property
    def recon_dir(self) -> Path:
        return self.root / RECON_DIR

    def views(self) -> list[int]:
        return sorted({f.view for f in self.frames})

    def frames_of_view(self, view: int) -> list[FrameRecord]:
        return [f for f in self.frames if f.view == view]
