"""``python -m companion run``: configuration, and a real process that starts and stops."""

from __future__ import annotations

import queue
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from companion.app.config import ConfigError, LinkSettings, load_config
from companion.mission.files import format_wpl
from companion.settings import CompanionSettings
from protocol.tools.cli import write_atomic
from tests.companion.missions import HOME, survey


def _companion(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "companion", *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


def identity(folder: Path, node: int) -> str:
    """Keys made with ``python -m companion keys`` as an operator would: an operator key, a
    drone key, the certificate; returns the config's [identity] and [[trust.operator]]."""
    for name in ("acme", f"drone{node}"):
        made = _companion("keys", "init", str(folder / f"{name}.key"))
        assert made.returncode == 0 and "fingerprint" in made.stdout, made.stderr
    cert = folder / f"drone{node}.cert"
    certify = _companion(
        "keys", "certify", "--operator-key", str(folder / "acme.key"),
        "--drone", str(folder / f"drone{node}.pub"), "--node", str(node), "--out", str(cert),
    )  # fmt: skip
    assert certify.returncode == 0, certify.stderr
    return (
        f'[identity]\nkey = "drone{node}.key"\ncertificate = "drone{node}.cert"\n'
        f'state_dir = "state"\n[[trust.operator]]\nname = "acme"\nkey = "acme.pub"\n'
    )


def test_keys_cli_and_identity_config(tmp_path: Path) -> None:
    config = tmp_path / "c.toml"
    section = identity(tmp_path, 4)
    config.write_text("node = 4\n" + section)
    loaded = load_config(config)
    assert loaded.credentials is not None
    cert = loaded.credentials.identity.cert
    assert cert.node == 4 and cert.fingerprint == loaded.credentials.identity.key.fingerprint
    (operator,) = loaded.credentials.trust.operators.values()
    assert operator.name == "acme" and cert.signed_by(operator.key)
    shown = _companion(
        "keys", "show", str(tmp_path / "drone4.cert"), "--operator", str(tmp_path / "acme.pub")
    )
    assert shown.returncode == 0 and "node 4" in shown.stdout and "good" in shown.stdout
    assert (tmp_path / "drone4.key").stat().st_mode & 0o777 == 0o600
    again = _companion("keys", "init", str(tmp_path / "drone4.key"))
    assert again.returncode == 2 and "exists" in again.stderr  # never overwritten silently
    with pytest.raises(ConfigError, match="node 4, not node 5"):
        load_config(config, {"node": 5})
    assert _companion("keys", "init", str(tmp_path / "other.key")).returncode == 0
    config.write_text("node = 4\n" + section.replace("drone4.key", "other.key"))
    with pytest.raises(ConfigError, match="another key"):
        load_config(config)


def test_the_config_example_says_the_defaults(tmp_path: Path) -> None:
    """The annotated example in companion.app.config's docstring gives every setting its
    default (no identity, no trust: those have none); a config without them loads the same,
    and both are the settings' own defaults."""
    import tomllib

    import companion.app.config as config_module

    assert config_module.__doc__ is not None
    example = config_module.__doc__.split("::", 1)[1].split('"""')[0]
    text = "\n".join(line[4:] for line in example.splitlines())
    cut = text.index("[identity]"), text.index("[limits]")
    tomllib.loads(text)  # the whole example is TOML
    example_path = tmp_path / "example.toml"
    example_path.write_text(text[: cut[0]] + text[cut[1] :])
    from_example = load_config(example_path)
    bare = load_config(None, {"node": 1})
    assert from_example == bare
    assert bare.companion == CompanionSettings(node=1, autopilot_url=bare.companion.autopilot_url)
    assert bare.link == LinkSettings()


def test_config_file_and_flags(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text(
        'node = 3\nautopilot = "udpin://0.0.0.0:14542"\not_security = 128\n'
        '[link]\nprofile = "eu868-sf7"\n'
        "[offset]\noffset_m = 15\nmax_levels = 2\n[limits]\nmax_runs_per_peer = 2\n"
    )
    config = load_config(path, {"link.profile": "us915-sf9", "offset.max_altitude_m": 90})
    assert config.companion.node == 3 and config.companion.offset.offset_m == 15.0
    assert config.link.profile == "us915-sf9"  # the flag wins
    assert config.companion.offset.max_altitude_m == 90.0
    assert config.companion.offset.max_levels == 2 and config.companion.offset.max_raise_m == 30
    assert load_config(None, {"node": 1}).companion.offset.max_levels is None  # to the ceiling
    assert config.companion.max_runs_per_peer == 2
    assert config.companion.ot_security == 128
    assert load_config(None, {"node": 1}).companion.ot_security == 112  # the default


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "c.toml: node: a node id"),
        ("node = 1\n[link]\nprofile = 'lora'\n", r"\[link\]: profile: 'lora' is not one of"),
        ("node = 1\n[link]\ntransport = 'wifi'\n", r"\[link\]: transport"),
        ("node = 1\n[offset]\noffset_m = -3\n", r"\[offset\]: offset_m: -3 is out of range"),
        ("node = 1\n[offset]\noffset_m = nan\n", "offset_m: nan is not a finite number"),
        ("node = 1\n[offset]\nmax_levels = -1\n", r"\[offset\]: max_levels: -1 is out of range"),
        ("node = 1\n[limits]\nmax_runs_per_peer = 'many'\n", "max_runs_per_peer"),
        ("node = 1\nlog_level = 'loud'\n", "log_level"),
        ("node = 1\not_security = 80\n", "ot_security"),
        ("node = [", "c.toml: not TOML"),
        ("nod = 1\n", "c.toml: unknown key 'nod' \\(did you mean 'node'\\?\\)"),
        ("node = 1\nnod = 1\n", "c.toml: unknown key 'nod' \\(did you mean 'node'\\?\\)"),
        ("node = 1\n[link]\nprofle = 'us915-sf9'\n", r"\[link\]: unknown key 'profle'"),
        ("node = 1\n[link]\nhub = 'localhost:99999'\n", r"\[link\]: hub: .*1..65535"),
        ("node = true\n", "node: expected an integer"),
    ],
)
def test_config_errors(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "c.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_config(path)


def _spawn(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "companion", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


_LINES: dict[int, queue.Queue[str]] = {}


def _lines(proc: subprocess.Popen[str]) -> queue.Queue[str]:
    """The process's output lines, read by a thread (a silent process cannot block a test)."""
    if proc.pid not in _LINES:
        lines: queue.Queue[str] = queue.Queue()
        stream = proc.stdout
        assert stream is not None

        def pump() -> None:
            for line in stream:
                lines.put(line)
            lines.put("")  # end of output

        threading.Thread(target=pump, daemon=True).start()
        _LINES[proc.pid] = lines
    return _LINES[proc.pid]


def _wait_for(proc: subprocess.Popen[str], pattern: str, seconds: float = 30) -> str:
    lines = _lines(proc)
    deadline = time.monotonic() + seconds
    seen = []
    while time.monotonic() < deadline:
        try:
            line = lines.get(timeout=max(deadline - time.monotonic(), 0.01))
        except queue.Empty:
            break
        if not line:
            break
        seen.append(line)
        if re.search(pattern, line):
            return line
    raise AssertionError(f"{pattern!r} not seen in:\n{''.join(seen)[-3000:]}")


@pytest.mark.slow
def test_companion_process_starts_and_stops_cleanly(tmp_path: Path) -> None:
    mission = tmp_path / "m.txt"
    write_atomic(mission, format_wpl(survey(6), HOME))
    hub = _spawn("link-hub", "--port", "0")
    mock = _spawn("mock-autopilot", "--mission", str(mission), "--instance", "43")
    try:
        address = re.search(r"udp://([\d.]+:\d+)", _wait_for(hub, "link hub on"))
        assert address
        _wait_for(mock, "mock PX4 autopilot")
        config = tmp_path / "c.toml"
        config.write_text(
            f'node = 7\nautopilot = "udpin://127.0.0.1:{14540 + 43}"\n'
            f'[link]\nhub = "{address.group(1)}"\n' + identity(tmp_path, 7)
        )
        companion = _spawn("run", "--config", str(config))
        try:
            _wait_for(companion, r"node 7: mission \(.*segments=4")
            _wait_for(companion, "running")
            companion.send_signal(signal.SIGTERM)
            _wait_for(companion, "stopping")
            assert companion.wait(30) == 0
        finally:
            companion.kill()
    finally:
        for proc in (hub, mock):
            proc.terminate()
            proc.wait(30)


def test_no_autopilot_is_a_clear_error(tmp_path: Path) -> None:
    config = tmp_path / "c.toml"
    config.write_text(
        'node = 7\nautopilot = "udpin://127.0.0.1:14599"\nautopilot_connect_s = 1.5\n'
        '[link]\nhub = "127.0.0.1:9"\n' + identity(tmp_path, 7)
    )
    run = _companion("run", "--config", str(config))
    assert run.returncode == 2 and "no autopilot heard" in run.stderr  # the environment
    assert "within 1.5 s" in run.stderr
    config.write_text('node = 7\nautopilot = "udpin://127.0.0.1:14599"\n')
    anonymous = _companion("run", "--config", str(config))
    assert anonymous.returncode == 2 and "needs an identity" in anonymous.stderr
