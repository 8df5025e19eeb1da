"""``python -m companion keys init|certify|show``: drone and operator keys, certificates.

::

    python -m companion keys init acme.key                # an operator's key (and acme.pub)
    python -m companion keys init drone7.key              # a drone's key (and drone7.pub)
    python -m companion keys certify --operator-key acme.key --drone drone7.pub --node 7 \\
        --out drone7.cert                                 # the operator vouches for drone 7
    python -m companion keys show drone7.cert --operator acme.pub

The drone's config names its key and certificate (``[identity]``) and the operators it trusts
(``[[trust.operator]]``, their ``.pub`` files); see ``companion/app/config.py``.
"""

from __future__ import annotations

import argparse
import datetime
import time
from pathlib import Path
from typing import Any

from companion.auth.certificate import SIZE as CERT_SIZE
from companion.auth.certificate import Certificate
from companion.auth.keys import (
    KeyFileError,
    PublicKey,
    public_pem,
    read_private_key,
    read_public_key,
)
from companion.auth.keys import SigningKey as Key
from protocol.tools import cli


def write_atomic(path: Path, data: bytes, mode: int = 0o644) -> None:
    """Write ``data`` to ``path`` whole or not at all (:func:`protocol.tools.cli.write_atomic`)."""
    path = Path(path)
    if not path.parent.is_dir():
        raise KeyFileError(f"{path}: directory {path.parent} does not exist")
    try:
        cli.write_atomic(path, data, mode)
    except OSError as exc:
        raise KeyFileError(f"{path}: {exc.strerror or exc}") from None


def write_private_key(path: Path, key: Key) -> None:
    write_atomic(path, key.pem(), 0o600)


def write_public_key(path: Path, key: PublicKey) -> None:
    write_atomic(path, public_pem(key))


def add_parser(sub: argparse._SubParsersAction[Any]) -> None:
    keys = sub.add_parser("keys", help="drone and operator keys, certificates")
    action = keys.add_subparsers(dest="action", required=True)
    init = action.add_parser("init", help="a new Ed25519 key: FILE (mode 0600) and its .pub")
    init.add_argument("file", help="private key file to create, e.g. drone7.key or acme.key")
    init.add_argument("--force", action="store_true", help="overwrite an existing key")
    certify = action.add_parser("certify", help="sign a drone's key with an operator key")
    certify.add_argument("--operator-key", required=True, help="the operator's private key")
    certify.add_argument("--drone", required=True, help="the drone's .pub (or .key) file")
    certify.add_argument(
        "--node", type=cli.integer(1, 0xFFFE), required=True, help="the drone's node id"
    )
    certify.add_argument(
        "--days", type=cli.number(0, 36_500, above=True), default=365.0, help="validity in days"
    )
    certify.add_argument(
        "--out", type=cli.output_file(), required=True, help="certificate file to write"
    )
    show = action.add_parser("show", help="what key and certificate files hold")
    show.add_argument("files", nargs="+", type=cli.existing_file, help="key or certificate files")
    show.add_argument("--operator", help="check certificates against this operator .pub file")
    keys.set_defaults(func=run)


def _public_of(path: Path) -> PublicKey:
    try:
        return read_public_key(path)
    except KeyFileError:
        return read_private_key(path).public  # a .key file works too


def _when(unix_s: int) -> str:
    return datetime.datetime.fromtimestamp(unix_s, datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")


def _describe(path: Path, operator: PublicKey | None) -> str:
    data = path.read_bytes()
    if len(data) == CERT_SIZE and not data.startswith(b"-----"):
        cert = Certificate.decode(data)
        now = time.time()
        lines = [
            f"{path}: certificate for node {cert.node}",
            f"  drone key fingerprint     {cert.fingerprint.hex()}",
            f"  operator key fingerprint  {cert.operator.hex()}",
            f"  valid {_when(cert.not_before)} .. {_when(cert.not_after)}"
            + ("" if cert.valid_at(now) else "  (NOT VALID NOW)"),
        ]
        if operator is not None:
            ok = cert.signed_by(operator)
            lines.append(f"  signature by {operator.fingerprint.hex()}: {'good' if ok else 'BAD'}")
        return "\n".join(lines)
    if b"PRIVATE KEY" in data:
        key = read_private_key(path)
        return f"{path}: private key, fingerprint {key.fingerprint.hex()}"
    public = read_public_key(path)
    return f"{path}: public key {public.raw.hex()}\n  fingerprint {public.fingerprint.hex()}"


def run(args: argparse.Namespace) -> int:
    """One action; failures raise (one line and exit 2 by :func:`protocol.tools.cli.run`)."""
    if args.action == "init":
        path = Path(args.file)
        public = path.with_suffix(".pub")
        if path.suffix == ".pub":
            raise cli.InputError(f"{path}: name the private key file, not .pub")
        for existing in (path, public):
            if existing.exists() and not args.force:
                raise cli.InputError(f"{existing} exists (--force to overwrite)")
        key = Key.generate()
        write_private_key(path, key)
        write_public_key(public, key.public)
        print(f"{path}: new key, fingerprint {key.fingerprint.hex()} (public: {public})")
        return 0
    if args.action == "certify":
        operator = read_private_key(Path(args.operator_key))
        drone = _public_of(Path(args.drone))
        start = int(time.time()) - 300  # five minutes of clock error between drones
        cert = Certificate.issue(operator, drone, args.node, start, start + int(args.days * 86400))
        write_atomic(Path(args.out), cert.encode())
        print(
            f"{args.out}: node {args.node}, drone {cert.fingerprint.hex()} certified by "
            f"{operator.fingerprint.hex()} until {_when(cert.not_after)}"
        )
        return 0
    operator_key = _public_of(Path(args.operator)) if args.operator else None
    for name in args.files:
        print(_describe(Path(name), operator_key))
    return 0
