"""What every command line of the project shares: one error style, checked flags, safe output.

Rules:

1. Exit codes mean one thing everywhere: 0 success; 1 the command's documented negative
   answer (a case disagrees, a conflict was not resolved, a replay did not finish); 2 the
   input or the environment is wrong; 3 a bug.
2. Expected failures (:data:`EXPECTED`: bad files, flags, configs, ports) are one line on
   stderr, ``error: WHERE: what is wrong (hint)``, and never a traceback unless ``--debug``.
3. Flags are checked when they are parsed, before any work starts: numbers are finite and in
   range, output files can be written (their directory exists), input files exist.
4. Files are written whole or not at all (:func:`write_atomic`).
"""

from __future__ import annotations

import argparse
import errno
import ipaddress
import math
import os
import socket
import sys
import tempfile
import traceback
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import NoReturn

from protocol.errors import ProtocolError

EXIT_OK, EXIT_NEGATIVE, EXIT_INPUT, EXIT_BUG = 0, 1, 2, 3
EXIT_INTERRUPTED = 130
DISTRIBUTION = "private-deconfliction"
EPILOG = (
    "exit codes: 0 success, 1 a negative answer (see the command), 2 bad input or environment, "
    "3 a bug (--debug shows its traceback)"
)


class InputError(ProtocolError):
    """Bad input named by where it is (a file, a flag, a key): one line, exit 2."""


# What a command reports as one line and exit 2: the package's own errors (a caller adds its
# package's root, the companion its CompanionError) and OSError for files and sockets.  Any
# other exception is a bug.
EXPECTED: tuple[type[BaseException], ...] = (OSError, ProtocolError)

_OS_HINTS = {
    errno.EADDRINUSE: "another process uses this address: stop it or choose another port",
    errno.EADDRNOTAVAIL: "this machine has no such address: use 127.0.0.1 or 0.0.0.0",
    errno.EACCES: "permission denied: check the file's or port's permissions",
    errno.ECONNREFUSED: "nothing listens there: start it first",
}


def version() -> str:
    """The installed distribution's version (the source tree's if it is not installed)."""
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:  # pragma: no cover - run from a bare checkout
        return "0+unknown"


def describe(exc: BaseException) -> str:
    """``exc`` as one line: an OSError with its file and a hint, anything else its text."""
    if isinstance(exc, OSError) and exc.strerror:
        where = f"{exc.filename}: " if exc.filename else ""
        hint = _OS_HINTS.get(exc.errno or 0)
        text = f"{where}{exc.strerror}" + (f" ({hint})" if hint else "")
    else:
        text = str(exc) or type(exc).__name__
    return " ".join(text.split())


class HelpFormatter(argparse.HelpFormatter):
    """Help that shows each option's default, unless it has none or the help says it."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        # by identity: a default of 0 or 0.0 equals False, and must be shown all the same
        if default is None or default is False or default is argparse.SUPPRESS:
            return text
        if "default" in text or not action.option_strings:
            return text
        return f"{text} (default: %(default)s)"


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, like every other error, and whose
    help shows each option's default."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        kwargs.setdefault("epilog", EPILOG)
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]

    def error(self, message: str) -> NoReturn:
        print(f"error: {self.prog}: {message} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(EXIT_INPUT)


def add_common(parser: argparse.ArgumentParser) -> None:
    """``--version``, and ``--debug`` (tracebacks for expected errors too) on the command and
    every sub-command, so it may come anywhere on the line.  Call once all are added."""
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks (for bug reports)")
    _debug_everywhere(parser)


def _debug_everywhere(parser: argparse.ArgumentParser) -> None:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                if "--debug" not in child._option_string_actions:
                    child.add_argument(
                        "--debug",
                        action="store_true",
                        default=argparse.SUPPRESS,  # not to hide the command's own --debug
                        help="show tracebacks (for bug reports)",
                    )
                _debug_everywhere(child)


def run(
    command: Callable[[argparse.Namespace], int],
    args: argparse.Namespace,
    expected: tuple[type[BaseException], ...] = (),
) -> int:
    """Run ``command(args)`` under rule 2: expected failures (:data:`EXPECTED` and
    ``expected``) are one line and exit 2, anything else a bug (exit 3), Ctrl-C 130."""
    debug = bool(getattr(args, "debug", False))
    try:
        return command(args)
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except EXPECTED + expected as exc:
        if debug:
            traceback.print_exc()
        print(f"error: {describe(exc)}", file=sys.stderr)
        return EXIT_INPUT
    except Exception as exc:
        if debug:
            traceback.print_exc()
        print(
            f"error: internal error: {type(exc).__name__}: {describe(exc)} (a bug: run again "
            "with --debug and report the traceback)",
            file=sys.stderr,
        )
        return EXIT_BUG


# ------------------------------------------------------------------ flag types (rule 3)


def number(
    low: float | None = None,
    high: float | None = None,
    *,
    above: bool = False,
    below: bool = False,
) -> Callable[[str], float]:
    """A finite number in [low, high] (``above``/``below``: the bound itself excluded)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
        _check_range(value, low, high, above, below)
        return value

    return parse


def integer(low: int | None = None, high: int | None = None) -> Callable[[str], int]:
    """An integer in [low, high]."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        _check_range(value, low, high, False, False)
        return value

    return parse


def _check_range(
    value: float, low: float | None, high: float | None, above: bool, below: bool
) -> None:
    if low is not None and (value < low or (above and value == low)):
        bound = f"above {low:g}" if above else f"at least {low:g}"
        raise argparse.ArgumentTypeError(f"{value:g} is out of range: must be {bound}")
    if high is not None and (value > high or (below and value == high)):
        bound = f"below {high:g}" if below else f"at most {high:g}"
        raise argparse.ArgumentTypeError(f"{value:g} is out of range: must be {bound}")


probability = number(0.0, 1.0, below=True)  # a loss or corruption rate: 1 would mean no link
port = integer(1, 65535)
listen_port = integer(0, 65535)  # 0: any free port, which the program then prints
seed = integer(0, 2**64 - 1)


def host(text: str) -> str:
    """An address to bind or reach: an IP address, or a host name this machine resolves."""
    try:
        ipaddress.ip_address(text)
        return text
    except ValueError:
        pass
    try:
        socket.getaddrinfo(text, None, type=socket.SOCK_DGRAM)
    except (OSError, UnicodeError):
        raise argparse.ArgumentTypeError(
            f"{text!r} is neither an IP address nor a known host name (e.g. 127.0.0.1 for "
            "this machine, 0.0.0.0 for every interface)"
        ) from None
    return text


class Moved(argparse.Action):
    """An option that moved to another command: using it is an error that says where to
    (rather than argparse's guess, which reads its value as the next positional argument)."""

    def __init__(self, option_strings: list[str], dest: str, *, to: str, **kwargs: object) -> None:
        kwargs.update(nargs="?", help=argparse.SUPPRESS, default=argparse.SUPPRESS)
        super().__init__(option_strings, dest, **kwargs)  # type: ignore[arg-type]
        self.to = to

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: object,
        option_string: str | None = None,
    ) -> None:
        parser.error(f"{option_string}: no such option here: {self.to}")


def integers(low: int, high: int) -> Callable[[str], tuple[int, ...]]:
    """Comma-separated integers, each in [low, high]."""
    one = integer(low, high)

    def parse(text: str) -> tuple[int, ...]:
        parts = text.split(",")
        if not text or any(not p.strip() for p in parts):
            raise argparse.ArgumentTypeError(f"{text!r}: expected integers separated by commas")
        return tuple(one(p.strip()) for p in parts)

    return parse


def existing_file(text: str) -> Path:
    """An input file that exists and is a file."""
    path = Path(text)
    if not path.is_file():
        what = "is a directory" if path.is_dir() else "does not exist"
        raise argparse.ArgumentTypeError(f"{text}: {what}")
    return path


def existing_dir(text: str) -> Path:
    """An input directory that exists."""
    path = Path(text)
    if not path.is_dir():
        what = "is not a directory" if path.exists() else "does not exist"
        raise argparse.ArgumentTypeError(f"{text}: {what}")
    return path


def output_file(*suffixes: str) -> Callable[[str], Path]:
    """A file to write: its directory exists and is writable, its name ends in one of
    ``suffixes`` (any, if none are given).  Nothing is created here."""

    def parse(text: str) -> Path:
        path = Path(text)
        if suffixes and path.suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(
                f"{text}: the file name must end in {' or '.join(suffixes)}"
            )
        _writable_dir(path.parent, text)
        if path.is_dir():
            raise argparse.ArgumentTypeError(f"{text}: is a directory")
        return path

    return parse


def output_dir(text: str) -> Path:
    """A directory to write into: it exists, or its parent does (it is created at the end)."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: exists and is not a directory")
    _writable_dir(path if path.is_dir() else path.parent, text)
    return path


def _writable_dir(directory: Path, text: str) -> None:
    directory = directory if str(directory) else Path(".")
    if not directory.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: directory {directory} does not exist")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{text}: directory {directory} is not writable")


def write_atomic(path: str | Path, data: bytes | str, mode: int = 0o644) -> None:
    """Write ``data`` through a temporary file beside ``path``: the file is the old one or the
    whole new one, never half written, and nothing is left behind on failure."""
    target = Path(path)
    payload = data.encode("utf-8") if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent)
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "wb") as handle:
            handle.write(payload)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
