"""The capture side of the session directory: create it and snapshot what the run depends
on (profile, calibration, software, devices); rig.capture.resume prepares a resume."""

from __future__ import annotations

import datetime as dt
import importlib
import platform
import shutil
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from core.errors import RigError
from core.files import temporary_name, write_bytes_atomically
from core.lock import LOCK_FILE
from core.manifest import MANIFEST_FILE
from core.session import CALIBRATION_DIR, POSES_DIR, RAW_DIR, SESSION_FILE
from core.yamlio import load_yaml
from rig import __version__
from rig.capture.frames import INCOMING
from rig.profile import CalibrationChoice, Profile, parse_profile

if TYPE_CHECKING:
    from calibration.store import CalibrationStore

FORMAT_VERSION = 1
GROUND_TRUTH_DIR = "ground_truth"  # sim sessions only: the true scene, for evaluation


def now() -> str:
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")


def software_versions() -> dict[str, str]:
    """Versions that can change what a session's files mean, for provenance."""
    versions = {
        "spectral-rig": __version__,
        "python": sys.version.split()[0],
        "platform": platform.platform(),
    }
    for module in ("numpy", "scipy", "rawpy", "colour", "pycolmap", "trimesh", "tifffile"):
        try:
            versions[module] = str(importlib.import_module(module).__version__)
        except (ImportError, AttributeError):
            continue
    try:
        import rawpy

        versions["libraw"] = ".".join(map(str, rawpy.libraw_version))
    except (ImportError, AttributeError):
        pass
    return versions


def write_info(session_dir: Path, info: dict[str, Any]) -> None:
    text = yaml.safe_dump(info, sort_keys=False, allow_unicode=True)
    write_bytes_atomically(session_dir / SESSION_FILE, text.encode("utf-8"))


def read_info(session_dir: Path) -> dict[str, Any]:
    path = session_dir / SESSION_FILE
    try:
        info = load_yaml(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise RigError(
            f"{path} cannot be read ({exc})",
            "restore it from a backup; the frames in raw/ are intact",
        ) from exc
    if not isinstance(info, dict) or "profile" not in info:
        raise RigError(
            f"{path} has no profile snapshot",
            "it was not written by `rig capture`; start a new session",
        )
    return info


def snapshot_profile(session_dir: Path) -> Profile:
    """The profile the session was started with (a resume never re-reads the profile file)."""
    info = read_info(session_dir)
    return parse_profile(info["profile"], f"{session_dir / SESSION_FILE} (profile snapshot)")


def check_new_session_dir(out_dir: Path) -> None:
    """``out_dir`` must be new or empty but for its lock (checked before any device is
    opened)."""
    if out_dir.exists() and any(p.name != LOCK_FILE for p in out_dir.iterdir()):
        if (out_dir / SESSION_FILE).exists():
            raise RigError(
                f"{out_dir} already holds a capture session",
                f"continue it with `rig capture --resume {out_dir}` or choose a new --out folder",
            )
        raise RigError(f"{out_dir} exists and is not empty", "choose a new --out folder")


def discard_unstarted_session(out_dir: Path) -> None:
    """Remove what a capture killed before writing session.yaml left behind (no frame can be
    recorded by then); refuse anything that is not such a leftover."""
    if not out_dir.exists():
        return
    leftovers = {
        RAW_DIR,
        CALIBRATION_DIR,
        GROUND_TRUTH_DIR,
        POSES_DIR,
        MANIFEST_FILE,
        f".{SESSION_FILE}.tmp",  # an older version's temporary name
        temporary_name(Path(SESSION_FILE)).name,
        LOCK_FILE,
    }
    foreign = sorted(p.name for p in out_dir.iterdir() if p.name not in leftovers)
    manifest = out_dir / MANIFEST_FILE
    if foreign or (manifest.is_file() and manifest.stat().st_size > 0):
        raise RigError(
            f"{out_dir} is not a capture session (no {SESSION_FILE}"
            + (f"; it holds {', '.join(foreign[:3])}" if foreign else "")
            + ")",
            "give the folder `rig capture --out` created, or start a new session with --out",
        )
    raw = out_dir / RAW_DIR
    files = sorted(p for p in raw.rglob("*") if p.is_file()) if raw.is_dir() else []
    if files:  # session.yaml removed after frames were taken: never delete them
        raise RigError(
            f"{out_dir} has no {SESSION_FILE} but holds {len(files)} file(s) under {RAW_DIR}/ "
            f"(first: {files[0].relative_to(out_dir)}); nothing was deleted",
            f"restore {SESSION_FILE} from a backup and resume, or move the frames elsewhere "
            "and start a new session",
        )
    for path in out_dir.iterdir():
        if path.name != LOCK_FILE:  # held by this capture
            shutil.rmtree(path) if path.is_dir() else path.unlink()


def new_session_dir(out_dir: Path) -> None:
    """Create ``out_dir`` with raw/ and raw/.incoming/."""
    check_new_session_dir(out_dir)
    (out_dir / RAW_DIR / INCOMING).mkdir(parents=True, exist_ok=True)


def snapshot_calibration(
    choice: CalibrationChoice | None, session_dir: Path, profile_source: str
) -> dict[str, Any]:
    """Copy the calibration entries the profile uses into SESSION/calibration/."""
    if choice is None:
        return {"snapshot": None, "note": "the profile names no calibration"}
    try:
        from calibration.store import CalibrationStore
    except ImportError as exc:
        raise RigError(
            "the calibration store (calibration.store) is not available",
            "install spectral-rig completely",
        ) from exc
    dest = session_dir / CALIBRATION_DIR
    if choice.store == "default":
        store = CalibrationStore.create_default(dest)
    else:
        root = Path(choice.store).expanduser()
        if not root.is_absolute():
            root = Path(profile_source).parent / root
        if not root.is_dir():
            raise RigError(
                f"{profile_source}: calibration.store {root} is not a directory",
                "run `rig calibrate wizard` to create it, or use store: default",
            )
        store = CalibrationStore(root)
    entries = {"camera": choice.camera, "lights": dict(choice.lights)}
    try:
        store.camera(choice.camera)
        for entry in choice.lights.values():
            store.light_spd(entry)
    except RigError as exc:
        raise RigError(
            f"{profile_source}: calibration entry missing: {exc.problem}",
            "add it with `rig calibrate wizard` or fix calibration.lights",
        ) from exc
    flat = _flat_field_record(choice, store, profile_source)
    if choice.store != "default":
        store.copy_to(dest)
    return {"store": choice.store, "snapshot": CALIBRATION_DIR, **entries, "flat_field": flat}


def _flat_field_record(
    choice: CalibrationChoice, store: CalibrationStore, profile_source: str
) -> dict[str, Any] | None:
    """session.yaml's ``calibration.flat_field``: the entry decode divides the frames by."""
    if choice.flat_field is None:
        return None
    if choice.store == "default":
        raise RigError(
            f"{profile_source}: calibration.flat_field {choice.flat_field!r} needs a calibration "
            "store of your own (the built-in one holds none)",
            "set calibration.store to the store `rig calibrate flat-field` or the wizard wrote",
        )
    try:
        entry, flat = store.flat_field(choice.flat_field)
    except RigError as exc:
        raise RigError(
            f"{profile_source}: calibration.flat_field: {exc.problem}",
            "make it with `rig calibrate flat-field` or `rig calibrate wizard`, or remove the key",
        ) from exc
    return {"entry": entry.name, "version": entry.version, "method": flat.method}
