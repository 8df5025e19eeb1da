"""Keys, key files, certificates and the trust store."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.auth.certificate import SIZE, Certificate, CertificateError
from companion.auth.keys import (
    KeyFileError,
    PublicKey,
    SigningKey,
    read_private_key,
    read_public_key,
)
from companion.auth.trust import Operator, TrustStore, Untrusted, UntrustedPeer
from companion.cli.keys import write_private_key, write_public_key

NOW = int(time.time())


def test_key_files_round_trip_private_0600(tmp_path: Path) -> None:
    key = SigningKey.generate()
    write_private_key(tmp_path / "d.key", key)
    write_public_key(tmp_path / "d.pub", key.public)
    assert (tmp_path / "d.key").stat().st_mode & 0o777 == 0o600
    assert read_private_key(tmp_path / "d.key").public == key.public
    assert read_public_key(tmp_path / "d.pub") == key.public
    (tmp_path / "hex.pub").write_text(key.public.raw.hex() + "\n")
    assert read_public_key(tmp_path / "hex.pub") == key.public
    assert not list(tmp_path.glob(".*"))  # no temporary file left behind


@pytest.mark.parametrize(
    ("content", "message"),
    [(b"", "not an unencrypted PEM"), (b"-----BEGIN PRIVATE KEY-----\nxx", "not an unencrypted")],
)
def test_bad_key_files_name_the_file(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "bad.key"
    path.write_bytes(content)
    with pytest.raises(KeyFileError, match=f"{path}: {message}"):
        read_private_key(path)
    with pytest.raises(KeyFileError, match=r"missing\.key"):
        read_private_key(tmp_path / "missing.key")
    with pytest.raises(KeyFileError, match="does not exist"):
        write_private_key(tmp_path / "no" / "dir.key", SigningKey.generate())


def test_certificate_round_trip_and_signature() -> None:
    operator, drone = SigningKey.generate(), SigningKey.generate()
    cert = Certificate.issue(operator, drone.public, 7, NOW - 10, NOW + 3600)
    wire = cert.encode()
    assert len(wire) == SIZE == 115
    back = Certificate.decode(wire)
    assert back == cert and back.signed_by(operator.public)
    assert not back.signed_by(SigningKey.generate().public)
    for k in range(len(wire)):  # any change to any byte breaks it
        bad = bytearray(wire)
        bad[k] ^= 0x01
        try:
            changed = Certificate.decode(bytes(bad))
        except CertificateError:
            continue
        assert not changed.signed_by(operator.public)
    with pytest.raises(CertificateError):
        Certificate.issue(operator, drone.public, 0xFFFF, NOW, NOW + 1)  # the broadcast id
    with pytest.raises(CertificateError):
        Certificate.issue(operator, drone.public, 1, NOW, NOW - 1)


@settings(max_examples=300)
@given(st.binary(max_size=200))
def test_certificate_decoder_fuzz(data: bytes) -> None:
    try:
        Certificate.decode(data)
    except CertificateError:
        pass


def test_trust_store_reasons() -> None:
    acme, rogue, drone = SigningKey.generate(), SigningKey.generate(), SigningKey.generate()
    store = TrustStore([Operator("acme", acme.public, max_segments=16)])
    good = Certificate.issue(acme, drone.public, 5, NOW - 10, NOW + 100)
    assert store.check(good, 5, NOW).name == "acme"
    cases = [
        (Certificate.issue(rogue, drone.public, 5, NOW - 10, NOW + 100), 5, NOW),
        (good, 6, NOW),
        (good, 5, NOW + 1000),
        (good, 5, NOW - 1000),
        (Certificate(5, drone.public, acme.fingerprint, NOW - 10, NOW + 100, bytes(64)), 5, NOW),
    ]
    reasons = [
        Untrusted.UNKNOWN_OPERATOR,
        Untrusted.WRONG_NODE,
        Untrusted.EXPIRED,
        Untrusted.NOT_YET_VALID,
        Untrusted.BAD_SIGNATURE,
    ]
    for (cert, node, now), reason in zip(cases, reasons, strict=True):
        with pytest.raises(UntrustedPeer) as info:
            store.check(cert, node, now)
        assert info.value.reason is reason
    with pytest.raises(ValueError, match="max_segments"):
        Operator("x", acme.public, max_segments=0)
    with pytest.raises(ValueError, match="64 hex"):
        PublicKey.parse("zz")
