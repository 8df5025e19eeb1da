"""Logs people and machines read: ``key=value`` lines on stderr, JSON lines in a file.

A log call that carries structure passes it as ``extra={"event": KIND, "fields": {...}}``
(:func:`event`); the text line shows the fields as ``key=value`` and the JSON-lines file
(``--log-json FILE``) writes one object per record with its time, level, logger, event and
fields, so a flight's story can be read back without parsing text.  Field names carry their
unit (``_s``, ``_m``, ``_m_amsl``, ``_bytes``).
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

TEXT_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


def event(
    log: logging.Logger, level: int, kind: str, text: str, *, show: bool = True, **fields: Any
) -> None:
    """Log ``text`` followed by ``fields`` as key=value (unless ``show`` is false: the text
    says it already), with both kept for JSON lines."""
    if not log.isEnabledFor(level):
        return
    shown = " ".join(f"{k}={_short(v)}" for k, v in fields.items() if v is not None and show)
    log.log(
        level,
        "%s%s",
        text,
        f" ({shown})" if shown else "",
        extra={"event": kind, "fields": dict(fields)},
    )


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list | tuple) and len(value) > 12:
        return f"[{', '.join(map(str, value[:12]))}, ... {len(value)} in all]"
    return str(value)


def _plain(value: Any) -> Any:
    """JSON-safe: non-finite floats as null, sets and tuples as lists, keys as strings."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        items = sorted(value) if isinstance(value, set | frozenset) else value
        return [_plain(v) for v in items]
    if isinstance(value, str | int | bool) or value is None:
        return value
    return str(value)


class JsonLines(logging.Formatter):
    """One JSON object per record: t_unix_s, level, logger, message, event, fields."""

    def format(self, record: logging.LogRecord) -> str:
        entry: dict[str, Any] = {
            "t_unix_s": round(record.created, 3),
            "level": record.levelname.lower(),
            "logger": record.name,
            "message": record.getMessage(),
        }
        kind = getattr(record, "event", None)
        if kind is not None:
            entry["event"] = kind
            entry["fields"] = _plain(getattr(record, "fields", {}))
        if record.exc_info:
            entry["error"] = self.formatException(record.exc_info)
        return json.dumps(entry, separators=(",", ":"))


def setup(
    level: str = "info",
    json_file: Path | None = None,
    *,
    stderr_level: str | None = None,
    mavsdk: bool = False,
) -> None:
    """Text on stderr at ``stderr_level`` (default ``level``) and, if given, every record at
    ``level`` as JSON lines appended to ``json_file``.  With ``mavsdk`` the MAVSDK library's
    own log (printed by its C++ core otherwise) goes through logger ``mavsdk`` too."""
    root = logging.getLogger()
    for handler in list(root.handlers):
        root.removeHandler(handler)
    text_level = logging.getLevelName((stderr_level or level).upper())
    file_level = logging.getLevelName(level.upper())
    root.setLevel(min(text_level, file_level) if json_file is not None else text_level)
    text = logging.StreamHandler()
    formatter = logging.Formatter(TEXT_FORMAT)
    formatter.converter = time.gmtime  # UTC, as the JSON lines' Unix times
    text.setFormatter(formatter)
    text.setLevel(text_level)
    root.addHandler(text)
    if json_file is not None:
        lines = logging.FileHandler(json_file, encoding="utf-8")  # flushed at every record
        lines.setFormatter(JsonLines())
        lines.setLevel(file_level)
        root.addHandler(lines)
    if mavsdk:
        _route_mavsdk()


def _route_mavsdk() -> None:
    """MAVSDK's C++ log into Python logging (its INFO lines as DEBUG: connection chatter)."""
    import mavsdk

    library = logging.getLogger("mavsdk")
    levels = {0: logging.DEBUG, 1: logging.DEBUG, 2: logging.WARNING, 3: logging.ERROR}

    def forward(level: int, message: str, file: str | None, line: int) -> bool:
        library.log(levels.get(int(level), logging.INFO), "%s", message)
        return True  # handled: the library prints nothing itself

    mavsdk.log_subscribe(forward)
