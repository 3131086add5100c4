"""Every API key has a non-secret name: its fingerprint, or one given by fingerprint in
LTAA_API_KEY_NAMES. Names, never keys, are what the service stores."""

from __future__ import annotations

import hashlib

import pytest
from pydantic import SecretStr

from app.config import Settings
from app.http.auth import ApiKeysError, KeyRing, Role, key_fingerprint, parse_key_names

ALICE_KEY = "sup:er:visor-key-with-colons-01"  # keys may contain colons
SITE_KEY = "site-app-key-0123456789abcdef"


def _ring(names: str | None) -> KeyRing:
    settings = Settings(
        api_keys=SecretStr(f"{ALICE_KEY}:supervisor,{SITE_KEY}:client"), api_key_names=names
    )
    return KeyRing.from_settings(settings)


def test_the_default_name_is_a_short_fingerprint_that_does_not_hold_the_key() -> None:
    name = key_fingerprint(ALICE_KEY)
    assert name == "key-" + hashlib.sha256(ALICE_KEY.encode()).hexdigest()[:8]
    assert ALICE_KEY not in name and len(name) == 12
    assert _ring(None).identify(ALICE_KEY) == (Role.SUPERVISOR, name)


def test_names_are_given_by_fingerprint_and_unnamed_keys_keep_theirs() -> None:
    ring = _ring(f"{key_fingerprint(ALICE_KEY)}=alice")
    assert ring.identify(ALICE_KEY) == (Role.SUPERVISOR, "alice")
    assert ring.identify(SITE_KEY) == (Role.CLIENT, key_fingerprint(SITE_KEY))
    assert ring.identify("not-a-configured-key-at-all") is None


@pytest.mark.parametrize(
    ("names", "message"),
    [
        ("alice", "is not FINGERPRINT=NAME"),
        ("key-00000000=alice", "fingerprint of no key"),
        (f"{key_fingerprint(ALICE_KEY)}=x,{key_fingerprint(ALICE_KEY)}=y", "repeats"),
        (f"{key_fingerprint(ALICE_KEY)}=same,{key_fingerprint(SITE_KEY)}=same", "same name"),
        (f"{key_fingerprint(ALICE_KEY)}={'n' * 65}", "printable characters"),
    ],
)
def test_bad_names_fail_start_up_without_quoting_a_key(names: str, message: str) -> None:
    with pytest.raises(ApiKeysError, match=message) as err:
        _ring(names)
    assert ALICE_KEY not in str(err.value) and SITE_KEY not in str(err.value)


def test_parse_key_names_skips_blank_entries() -> None:
    assert parse_key_names(" key-1=a , ,key-2 = b ") == {"key-1": "a", "key-2": "b"}


def test_the_cli_prints_a_keys_fingerprint() -> None:
    from typer.testing import CliRunner

    from app.cli import cli

    result = CliRunner().invoke(cli, ["key-name", ALICE_KEY])
    assert result.exit_code == 0, result.output
    assert result.output.strip() == key_fingerprint(ALICE_KEY)
