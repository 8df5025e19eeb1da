"""Every command line, fed the ordinary mistakes of a new user: each must answer with one line
``error: ...`` on stderr and exit code 2, never a traceback, never a half-written file, and
before any work starts (protocol.tools.cli's rules).  Both packages' commands, one table."""

from __future__ import annotations

import argparse
import json
import math
import re
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

import companion.__main__ as companion_cli
import protocol.__main__ as protocol_cli
from companion.auth.certificate import Certificate
from companion.auth.keys import SigningKey
from companion.cli import commands
from companion.cli.keys import write_private_key, write_public_key

SCENARIOS = Path(__file__).resolve().parents[1] / "sitl_configs" / "scenarios"


@pytest.fixture
def files(tmp_path: Path) -> Path:
    """A directory of broken and good inputs."""
    good = json.loads((SCENARIOS / "delivery_east.plan").read_text())
    shutil.copy(SCENARIOS / "delivery_east.plan", tmp_path / "good.plan")
    shutil.copy(SCENARIOS / "inspection_north.plan", tmp_path / "other.plan")

    def variant(name: str, value: float, field: int) -> None:
        plan = json.loads(json.dumps(good))
        plan["mission"]["items"][1]["params"][field] = value
        (tmp_path / name).write_text(json.dumps(plan))  # json writes NaN and Infinity

    variant("nan.plan", math.nan, 4)
    variant("inf.plan", math.inf, 6)
    variant("high.plan", 1e6, 6)
    variant("lat200.plan", 200.0, 4)
    (tmp_path / "nan.waypoints").write_text(
        "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47.39\t8.54\t488\t1\n"
        "1\t0\t3\t16\t0\t0\t0\t0\tnan\t8.54\t30\t1\n"
    )
    scenario = (SCENARIOS / "crossing.toml").read_text()
    scenario = scenario.replace("inspection_north.plan", "other.plan")
    scenario = scenario.replace("delivery_east.plan", "good.plan")
    (tmp_path / "typo.toml").write_text(scenario.replace("takeoff_delay_s", "takeof_delay_s"))
    zero_scale, count = re.subn(r"(?m)^time_scale = .*$", "time_scale = 0", scenario)
    assert count == 1
    (tmp_path / "scale.toml").write_text(zero_scale)
    (tmp_path / "nanmission.toml").write_text(scenario.replace("good.plan", "nan.plan"))
    (tmp_path / "good.toml").write_text(scenario)
    (tmp_path / "config.toml").write_text("nod = 1\n")
    (tmp_path / "nomission.toml").write_text(scenario.replace("good.plan", "gone.plan"))
    identity = _identity(tmp_path, node=1)  # a config the companion would run with
    (tmp_path / "ident.toml").write_text("node = 1\n" + identity)
    (tmp_path / "badurl.toml").write_text('node = 1\nautopilot = "bogus://x"\n' + identity)
    (tmp_path / "badgrid.toml").write_text(
        "node = 1\n" + identity + "[limits]\nmin_grid_resolution_mm = 0\n"
    )
    (tmp_path / "paths.txt").write_text("(0,0)(10,10)\n")
    (tmp_path / "adir").mkdir()
    return tmp_path


def _identity(folder: Path, node: int) -> str:
    """An operator key, a drone key and its certificate for ``node`` in ``folder``: the
    config's [identity] and [[trust.operator]] (as ``keys init|certify`` make them)."""
    operator, drone = SigningKey.generate(), SigningKey.generate()
    write_private_key(folder / "drone.key", drone)
    write_public_key(folder / "acme.pub", operator.public)
    start = int(time.time()) - 300
    cert = Certificate.issue(operator, drone.public, node, start, start + 86400)
    (folder / "drone.cert").write_bytes(cert.encode())
    return (
        '[identity]\nkey = "drone.key"\ncertificate = "drone.cert"\nstate_dir = "state"\n'
        '[[trust.operator]]\nname = "acme"\nkey = "acme.pub"\n'
    )


C, P = "companion", "protocol"
RUN = ["run", "--config", "{d}/ident.toml", "--autopilot"]  # a config that would run
CASES: list[tuple[str, str, list[str], str]] = [
    # (id, package, argv with {d} for the files directory, what the line must say)
    ("plan-nan", C, ["mission", "show", "{d}/nan.plan"], "nan.plan: NaN is not a JSON number"),
    ("plan-inf", C, ["mission", "show", "{d}/inf.plan"], "inf.plan: Infinity is not a JSON"),
    ("plan-high", C, ["mission", "show", "{d}/high.plan"], "mission item 1: altitude 1e\\+06 m"),
    ("plan-lat", C, ["mission", "show", "{d}/lat200.plan"], "item 1: latitude/longitude out of"),
    ("wpl-nan", C, ["mission", "show", "{d}/nan.waypoints"], "line 3: latitude/longitude is not"),
    ("plan-missing", C, ["mission", "show", "{d}/missing.plan"], "missing.plan: does not exist"),
    ("plan-dir", C, ["mission", "show", "{d}/adir"], "adir: is a directory"),
    ("profiles", C, ["bench-link", "--profiles", "bogus"], "unknown link profile 'bogus'"),
    ("bench-pairs", C, ["bench-link", "--pairs", "0"], "--pairs: 0 is out of range"),
    ("compare-link", C, ["compare", "{d}/paths.txt", "{d}/paths.txt", "--link", "x"], "--link"),
    (
        "compare-mtu",
        C,
        ["compare", "{d}/paths.txt", "{d}/paths.txt", "--link", "us915-sf9", "--mtu", "222"],
        "--mtu 222: us915-sf9 carries at most",
    ),
    (
        "compare-range",
        C,
        ["compare", "{d}/paths.txt", "{d}/paths.txt", "--link", "ideal", "--range", "0"],
        "--range: 0 is out of range",
    ),
    (
        "compare-loss",
        C,
        ["compare", "{d}/paths.txt", "{d}/paths.txt", "--link", "ideal", "--loss", "1.5"],
        "--loss: 1.5 is out of range",
    ),
    ("run-no-node", C, ["run", "--autopilot", "udpin://0.0.0.0:14540"], "node: a node id 1..65534"),
    ("run-no-identity", C, ["run", "--node", "1"], "the companion needs an identity"),
    ("run-typo", C, ["run", "--config", "{d}/config.toml"], "unknown key 'nod' .did you mean"),
    ("run-node", C, ["run", "--node", "0"], "--node: 0 is out of range"),
    ("run-url-scheme", C, [*RUN, "bogus://x"], "--autopilot: bogus://x: not a MAVSDK connection"),
    ("run-url-port", C, [*RUN, "udpin://0.0.0.0:99999"], "with a port 1..65535"),
    ("run-url-port-0", C, [*RUN, "udpout://127.0.0.1:0"], "with a port 1..65535"),
    ("run-url-bind", C, [*RUN, "udpin://localhost:14540"], "udpin binds a local IP address"),
    (
        "run-url-serial",
        C,
        [*RUN, "serial:///dev/nonexist:57600"],
        "serial device /dev/nonexist does not exist",
    ),
    ("run-url-baud", C, [*RUN, "serial:///dev/null"], "expected serial://DEVICE:BAUD"),
    (
        "run-url-config",
        C,
        ["run", "--config", "{d}/badurl.toml"],
        "badurl.toml: autopilot: bogus://x: not a MAVSDK connection URL",
    ),
    (
        "run-grid-floor",
        C,
        ["run", "--config", "{d}/badgrid.toml"],
        "\\[limits\\]: min_grid_resolution_mm: 0 is out of range",
    ),
    ("hub-port", C, ["link-hub", "--port", "99999"], "--port: 99999 is out of range"),
    ("hub-loss", C, ["link-hub", "--loss", "nan"], "--loss: 'nan' is not a finite number"),
    ("hub-host", C, ["link-hub", "--host", "999.1.1.1"], "--host: '999.1.1.1' is neither an IP"),
    ("mock-ignore", C, ["mock-autopilot", "--ignore", "BOGUS_MSG"], "'BOGUS_MSG' is not a MAVL"),
    ("mock-ignore-typo", C, ["mock-autopilot", "--ignore", "MISION_COUNT"], "MISSION_COUNT\\?"),
    ("mock-drop-0", C, ["mock-autopilot", "--drop-every", "0"], "--drop-every: 0 is out of"),
    ("mock-instance-300", C, ["mock-autopilot", "--instance", "300"], "--instance: 300 is out"),
    ("mock-instance-neg", C, ["mock-autopilot", "--instance", "-20"], "--instance: -20 is out"),
    ("mock-scale-0", C, ["mock-autopilot", "--time-scale", "0"], "--time-scale: 0 is out"),
    ("mock-scale-neg", C, ["mock-autopilot", "--time-scale", "-5"], "--time-scale: -5 is out"),
    ("mock-speed", C, ["mock-autopilot", "--speed", "-3"], "--speed: -3 is out of range"),
    ("mock-lat", C, ["mock-autopilot", "--home-lat", "95"], "--home-lat: 95 is out of range"),
    ("mock-lat-nan", C, ["mock-autopilot", "--home-lat", "nan"], "'nan' is not a finite"),
    (
        "mock-trajectory",
        C,
        ["mock-autopilot", "--trajectory", "/nonexistent/dir/t.csv"],
        "directory /nonexistent/dir does not exist",
    ),
    ("mock-mission", C, ["mock-autopilot", "--mission", "{d}/missing.plan"], "does not exist"),
    ("replay-missing", C, ["replay", "{d}/missing.toml"], "missing.toml: does not exist"),
    (
        "replay-out",
        C,
        ["replay", "{d}/good.toml", "--out", "/nonexistent/dir/x.json"],
        "directory /nonexistent/dir does not exist",
    ),
    ("replay-out-dir", C, ["replay", "{d}/good.toml", "--out", "{d}/adir"], "must end in .json"),
    ("replay-plot", C, ["replay", "{d}/good.toml", "--plot", "{d}/x.gif"], "end in .png or .pdf"),
    ("replay-export", C, ["replay", "{d}/good.toml", "--export", "{d}/good.plan"], "not a dir"),
    (
        "replay-typo",
        C,
        ["replay", "{d}/typo.toml", "--out", "{d}/r.json"],
        "drone 1: unknown key 'takeof_delay_s' .did you mean 'takeoff_delay_s'",
    ),
    ("replay-scale", C, ["replay", "{d}/scale.toml"], "time_scale: 0 is out of range"),
    ("replay-nan", C, ["replay", "{d}/nanmission.toml"], "drone 1: .*nan.plan: NaN is not"),
    (
        "replay-no-plan",
        C,
        ["replay", "{d}/nomission.toml"],
        "nomission.toml: drone 1: mission: gone.plan does not exist \\(paths are relative",
    ),
    ("replay-speed", C, ["replay", "{d}/good.toml", "--px4-speed", "0"], "--px4-speed: 0 is"),
    (
        "keys-node",
        C,
        ["keys", "certify", "--operator-key", "k", "--drone", "d", "--node", "0", "--out", "c"],
        "--node: 0 is out of range",
    ),
    ("keys-show", C, ["keys", "show", "{d}/missing.pub"], "missing.pub: does not exist"),
    ("sizes-abc", P, ["bench", "scaling", "--sizes", "abc"], "'abc' is not an integer"),
    ("sizes-empty", P, ["bench", "scaling", "--sizes", "1,,2"], "expected integers separated"),
    ("sizes-zero", P, ["bench", "scaling", "--sizes", "0"], "0 is out of range"),
    ("repeat", P, ["bench", "crypto", "--repeat", "0"], "--repeat: 0 is out of range"),
    ("paper-no-data", P, ["bench", "paper"], "--data DIR is needed .the paper's benchmark files"),
    ("paper-data-gone", P, ["bench", "paper", "--data", "{d}/gone"], "--data: .*gone: does not"),
    ("paper-data-file", P, ["bench", "paper", "--data", "{d}/paths.txt"], "is not a directory"),
    ("paper-data-empty", P, ["bench", "paper", "--data", "{d}/adir"], "no alices_segments.txt"),
    ("link-data-empty", C, ["bench-link", "--data", "{d}/adir"], "adir: no alices_segments.txt"),
    ("p-compare-missing", P, ["compare", "{d}/missing.txt", "{d}/paths.txt"], "does not exist"),
    ("p-compare-plan", P, ["compare", "{d}/good.plan", "{d}/good.plan"], "python -m companion"),
    ("p-compare-range", P, ["compare", "{d}/paths.txt", "{d}/paths.txt", "--range", "0"], "0 is"),
    (
        "p-compare-loss",
        P,
        ["compare", "--loss", "0.2", "{d}/paths.txt", "{d}/paths.txt"],
        "--loss: no such option here: the radio options .* moved to `python -m companion compare`",
    ),
    (
        "p-compare-link",
        P,
        ["compare", "{d}/paths.txt", "{d}/paths.txt", "--link", "ideal"],
        "--link: no such option here",
    ),
]


def _main(package: str) -> Callable[[list[str]], int]:
    return companion_cli.main if package == C else protocol_cli.main


def _one_line_error(
    capsys: pytest.CaptureFixture[str], run: Callable[[], int | None]
) -> tuple[int, str]:
    try:
        code = run()
    except SystemExit as exc:  # argparse's own exit
        code = exc.code if isinstance(exc.code, int) else 2
    out, err = capsys.readouterr()
    assert code == 2, (code, out, err)
    assert "Traceback" not in err + out
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return code, lines[0]


@pytest.mark.parametrize(
    ("package", "argv", "message"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_bad_input_is_one_line_and_exit_2(
    files: Path,
    capsys: pytest.CaptureFixture[str],
    package: str,
    argv: list[str],
    message: str,
) -> None:
    args = [a.replace("{d}", str(files)) for a in argv]
    before = {p.name for p in files.iterdir()}
    _, line = _one_line_error(capsys, lambda: _main(package)(args))
    import re

    assert re.search(message, line), line
    assert {p.name for p in files.iterdir()} == before  # nothing written, nothing left over


def test_a_bug_is_exit_3_even_when_it_is_a_value_error(
    files: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Only the packages' own errors (and OSError) are bad input; a ValueError from a bug is
    reported as a bug."""

    def broken(*_: object) -> int:
        raise ValueError("a bug of ours")

    monkeypatch.setattr(commands, "mission_show", broken)
    mission = files / "m.plan"
    mission.write_text("{}")
    assert companion_cli.main(["mission", "show", str(mission)]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "error: internal error: ValueError: a bug of ours (a bug: run again with --debug and "
        "report the traceback)"
    ]


def test_address_in_use_says_so_with_a_hint(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        _, line = _one_line_error(
            capsys, lambda: companion_cli.main(["link-hub", "--port", str(port)])
        )
    assert "Address already in use" in line and "choose another port" in line


@pytest.mark.parametrize(
    ("url", "says"),
    [
        ("udpin://203.0.113.1:14540", "BIND_ERROR (is the address one of this machine's"),
        ("serial:///dev/null:57600", "CONNECTION_ERROR (is the device a serial port you may"),
    ],
)
def test_a_url_mavsdk_refuses_is_one_error_line(files: Path, url: str, says: str) -> None:
    """A well-formed URL MAVSDK cannot open (an address not this machine's, a device that is
    no serial port) ends as an expected error, exit 2, not a bug (exit 3).  In a process of
    its own: ``run`` sets up logging, whose lines come before the error (the last line)."""
    config = str(files / "ident.toml")
    result = subprocess.run(
        [sys.executable, "-m", "companion", "run", "--config", config, "--autopilot", url],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith(f"error: {url}: MAVSDK cannot connect: ") and says in last, last


def test_debug_shows_the_traceback(files: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = companion_cli.main(["mission", "show", str(files / "nan.plan"), "--debug"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" in err and err.strip().splitlines()[-1].startswith("error:")


@pytest.mark.parametrize("command", ["drone-deconflict", "drone-deconflict-protocol"])
def test_console_commands_are_installed(command: str) -> None:
    """The console scripts exist beside ``python -m``, and say their version."""
    exe = Path(sys.executable).parent / command
    assert exe.exists(), f"{exe}: pip install -e . installs the console commands"
    result = subprocess.run([str(exe), "--version"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and result.stdout.startswith(f"{command} 0."), result
    bad = subprocess.run([str(exe), "nonsense"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "Traceback" not in bad.stderr


def test_every_option_has_help() -> None:
    """Help on every option (its default shown by the formatter)."""
    import argparse

    def walk(parser: argparse.ArgumentParser, name: str) -> list[str]:
        missing = []
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for child_name, child in action.choices.items():
                    missing += walk(child, f"{name} {child_name}")
            elif action.help is None:
                missing.append(f"{name} {'/'.join(action.option_strings) or action.dest}")
        return missing

    assert walk(companion_cli._parser(), "companion") == []
    assert walk(protocol_cli._parser(), "protocol") == []


# Options that are off unless given (files to read or write): no default to show.
NO_DEFAULT = {"--mission", "--trajectory", "--out", "--plot", "--export", "--px4", "--log-json"}
NO_DEFAULT |= {"--config", "--operator", "--data"}


def _options(parser: argparse.ArgumentParser, name: str) -> list[tuple[str, argparse.Action, str]]:
    """(command, action, help as printed) of every option that takes a value."""
    found = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child_name, child in action.choices.items():
                found += _options(child, f"{name} {child_name}")
        elif action.option_strings and action.nargs != 0 and action.help != argparse.SUPPRESS:
            found.append((name, action, parser._get_formatter()._expand_help(action)))
    return found


def test_every_option_shows_its_default() -> None:
    """``--help`` shows each option's default (0 and 0.0 too), or says what happens without
    it; the run flags' defaults, which come from the config, name the config's own."""
    from companion.app.config import load_config

    options = _options(companion_cli._parser(), "companion")
    options += _options(protocol_cli._parser(), "protocol")
    missing = [
        f"{name} {action.option_strings[-1]}: {text!r}"
        for name, action, text in options
        if (action.default is not None and str(action.default) not in text)
        or (
            action.default is None
            and not action.required
            and "default" not in text
            and action.option_strings[-1] not in NO_DEFAULT
        )
    ]
    assert missing == []
    run = {a.option_strings[-1]: text for name, a, text in options if name == "companion run"}
    config = load_config(None, {"node": 1})
    link, settings = config.link, config.companion
    expected = {
        "--autopilot": settings.autopilot_url,
        "--transport": link.transport,
        "--profile": link.profile,
        "--hub": f"{link.hub[0]}:{link.hub[1]}",
        "--serial": link.serial,
        "--offset": str(settings.offset.offset_m),
        "--max-altitude": str(settings.offset.max_altitude_m),
    }
    for option, value in expected.items():
        assert f"else {value})" in run[option], (option, run[option])
