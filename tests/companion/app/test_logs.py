"""Logs: key=value text for people, one JSON object per line for machines."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import pytest

from companion import logs


@pytest.fixture
def restore_logging() -> object:
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    yield None
    for handler in list(root.handlers):
        root.removeHandler(handler)
        handler.close()
    for handler in handlers:
        root.addHandler(handler)
    root.setLevel(level)


def test_an_event_is_a_text_line_and_a_json_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], restore_logging: object
) -> None:
    path = tmp_path / "log.jsonl"
    logs.setup("info", path, stderr_level="warning")
    log = logging.getLogger("companion.test")
    logs.event(log, logging.INFO, "result", "node 1: result", peer=2, flagged={3, 1}, t_s=1.5)
    logs.event(log, logging.WARNING, "plan_failed", "node 1: plan failed", why=math.nan)
    log.debug("not written: below the file's level")
    err = capsys.readouterr().err
    assert "plan failed (why=nan)" in err and "result" not in err  # stderr: warnings only
    first, second = (json.loads(line) for line in path.read_text().splitlines())
    assert first["event"] == "result" and first["level"] == "info"
    assert first["fields"] == {"peer": 2, "flagged": [1, 3], "t_s": 1.5}
    assert first["message"] == "node 1: result (peer=2 flagged={1, 3} t_s=1.5)"
    assert second["fields"] == {"why": None}  # NaN is not JSON
    assert isinstance(first["t_unix_s"], float) and first["logger"] == "companion.test"
