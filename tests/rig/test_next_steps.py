"""What `rig demo` hands on: the next commands it prints, and its progress on a log."""

from __future__ import annotations

import io
import json
import os
import shlex
import socket
import time
from pathlib import Path

from rich.console import Console

from rig.cli import build_parser
from rig.next_steps import next_commands
from rig.progress_lines import ProgressLines


def test_next_commands_parse_and_name_the_demo_folder(tmp_path: Path) -> None:
    out = tmp_path / "demo out"  # a space: the printed commands quote it
    commands = next_commands(out, view=3)
    assert [c.split()[1] for c, _ in commands] == ["view", "relight", "export", "session"]
    parser = build_parser()
    for command, _ in commands:
        words = shlex.split(command)
        assert words[0] == "rig"
        args = parser.parse_args(words[1:])
        assert Path(getattr(args, "path", None) or args.session) == out
    assert parser.parse_args(shlex.split(commands[1][0])[1:]).view == 3


def _wait_for(stream: io.StringIO, text: str) -> str:
    for _ in range(500):
        if text in stream.getvalue():
            break
        time.sleep(0.01)
    return stream.getvalue()


def test_progress_lines_on_a_log_name_the_step_and_the_running_stage(tmp_path: Path) -> None:
    stream = io.StringIO()
    console = Console(file=stream, force_terminal=False, width=200)
    recon = tmp_path / "recon"
    recon.mkdir()
    status = {"status": "running", "pid": os.getpid(), "host": socket.gethostname(),
              "stage": "optimise"}
    (recon / "status.json").write_text(json.dumps(status))
    with ProgressLines(console, every_s=0.01, recon_dir=recon) as lines:
        lines.step("demo: reconstruction")
        text = _wait_for(stream, "(stage: optimise)")
    first = text.splitlines()[0]
    assert first.endswith("] demo: reconstruction") and first.startswith("[0:0")
    assert "demo: reconstruction (stage: optimise)" in text
    assert "\x1b[" not in text  # plain text, no terminal codes


def test_progress_lines_without_a_running_stage_repeat_the_step(tmp_path: Path) -> None:
    stream = io.StringIO()
    with ProgressLines(Console(file=stream, width=200), every_s=0.01, recon_dir=tmp_path) as lines:
        lines.step("demo: simulated capture")
        text = _wait_for(stream, "\n[")
    assert text.count("demo: simulated capture") >= 2 and "stage" not in text
