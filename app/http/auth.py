"""API keys and roles: who may call what.

`LTAA_API_KEYS` is a comma-separated list of `KEY:ROLE` entries, e.g.
`LTAA_API_KEYS="k3y-for-the-site-app:client,an0ther-k3y:supervisor"`. A `client` may allocate
and create and read runs; a `supervisor` may do everything (traces, resume, cancel, live
events, metrics). With no keys configured the API is open, which is allowed on a loopback
address only.

Every key has a non-secret name, stored wherever the service records who did something
(the reviewer of a decision, the signer of a sign-off); keys themselves are never stored.
The default name is the key's fingerprint, `key-` and the first 8 hex digits of its
SHA-256; `LTAA_API_KEY_NAMES` renames keys by fingerprint, e.g.
`LTAA_API_KEY_NAMES="key-3f2a9c1b=alice,key-9d8e7f6a=site-app"`, so that setting holds no
secret and the `KEY:ROLE` format of `LTAA_API_KEYS` (keys may contain colons) is unchanged.
`ltaa key-name KEY` prints a key's fingerprint.
"""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
from dataclasses import dataclass
from enum import StrEnum

from app.config import Settings

MIN_KEY_LENGTH = 16
KEY_HINT = "generate one with: python -c 'import secrets; print(secrets.token_urlsafe(32))'"


class Role(StrEnum):
    CLIENT = "client"
    SUPERVISOR = "supervisor"

    def allows(self, required: Role) -> bool:
        return self is Role.SUPERVISOR or required is Role.CLIENT


ANONYMOUS = "anonymous"  # the name recorded when access is open (no keys configured)
MAX_KEY_NAME_CHARS = 64


@dataclass(frozen=True)
class Caller:
    role: Role
    anonymous: bool  # open access (no keys configured), not an authenticated key
    name: str = ANONYMOUS  # the key's non-secret name: what records of who-did-what store


def key_fingerprint(key: str) -> str:
    """The default name of a key: short, stable, and telling nothing usable about it."""
    return "key-" + hashlib.sha256(key.encode("utf-8")).hexdigest()[:8]


class ApiKeysError(ValueError):
    """LTAA_API_KEYS cannot be parsed. Messages never quote the setting: it holds secrets."""


class InsecureBindError(RuntimeError):
    """The server would listen beyond loopback with no API keys: refuse to start."""


def _digest(key: str) -> bytes:
    # Comparing fixed-length digests keeps compare_digest's timing independent of key length.
    return hashlib.sha256(key.encode("utf-8")).digest()


def _session_fingerprint(digest: bytes) -> str:
    # Derived from the stored digest under its own label, so a console session row holds
    # neither the key nor the digest the API compares keys with.
    return hashlib.sha256(b"ltaa console session\0" + digest).hexdigest()


class KeyRing:
    def __init__(self, keys: dict[str, Role], names: dict[str, str] | None = None) -> None:
        """`names`: fingerprint -> name; a key not named there is called by its fingerprint."""
        names = names or {}
        fingerprints = {key_fingerprint(key) for key in keys}
        unknown = sorted(set(names) - fingerprints)
        if unknown:
            raise ApiKeysError(
                f"LTAA_API_KEY_NAMES names {', '.join(unknown)}, which is the fingerprint of "
                "no key in LTAA_API_KEYS (print a key's fingerprint with: ltaa key-name KEY)"
            )
        self._entries = [
            (_digest(key), role, names.get(key_fingerprint(key), key_fingerprint(key)))
            for key, role in keys.items()
        ]
        taken = [name for _, _, name in self._entries]
        if len(set(taken)) != len(taken):
            raise ApiKeysError("LTAA_API_KEY_NAMES gives two keys the same name")

    @classmethod
    def from_settings(cls, settings: Settings) -> KeyRing:
        raw = settings.api_keys.get_secret_value() if settings.api_keys else ""
        return cls(parse_api_keys(raw), parse_key_names(settings.api_key_names or ""))

    @property
    def open(self) -> bool:
        return not self._entries

    def identify(self, presented: str) -> tuple[Role, str] | None:
        """The role and name of a presented key, or None. Compares against every configured
        key (no early exit), so the time taken does not reveal which key, if any, nearly
        matched."""
        candidate = _digest(presented)
        found: tuple[Role, str] | None = None
        for digest, role, name in self._entries:
            if hmac.compare_digest(candidate, digest):
                found = (role, name)
        return found

    def role_of(self, presented: str) -> Role | None:
        found = self.identify(presented)
        return None if found is None else found[0]

    def fingerprint_of(self, presented: str) -> tuple[Role, str] | None:
        """The role of a presented key and a fingerprint to store with a console session
        (never the key), or None for an unknown key."""
        role = self.role_of(presented)
        return None if role is None else (role, _session_fingerprint(_digest(presented)))

    def identify_fingerprint(self, fingerprint: str) -> tuple[Role, str] | None:
        """The role and name of the configured key a session fingerprint was made from, or
        None once that key is no longer configured (which ends the session)."""
        found: tuple[Role, str] | None = None
        for digest, role, name in self._entries:
            if hmac.compare_digest(_session_fingerprint(digest), fingerprint):
                found = (role, name)
        return found

    def summary(self) -> str:
        counts = {role: sum(1 for _, r, _ in self._entries if r is role) for role in Role}
        return ", ".join(f"{n} {role.value}" for role, n in counts.items())


def parse_api_keys(raw: str) -> dict[str, Role]:
    """'KEY:ROLE,KEY:ROLE' -> {KEY: ROLE}. Entries are numbered in errors, never quoted."""
    keys: dict[str, Role] = {}
    roles = ", ".join(r.value for r in Role)
    for number, entry in enumerate((e.strip() for e in raw.split(",")), start=1):
        if not entry:
            continue
        # The role is after the *last* colon, so a key may itself contain colons.
        key, sep, role_name = entry.rpartition(":")
        key = key.strip()
        if not sep or not key:
            raise ApiKeysError(f"LTAA_API_KEYS entry {number} is not KEY:ROLE (roles: {roles})")
        try:
            role = Role(role_name.strip().lower())
        except ValueError:
            raise ApiKeysError(
                f"LTAA_API_KEYS entry {number} has an unknown role; use one of: {roles}"
            ) from None
        if len(key) < MIN_KEY_LENGTH:
            raise ApiKeysError(
                f"LTAA_API_KEYS entry {number}: keys must be at least "
                f"{MIN_KEY_LENGTH} characters; {KEY_HINT}"
            )
        if key in keys:
            raise ApiKeysError(f"LTAA_API_KEYS entry {number} repeats an earlier key")
        keys[key] = role
    return keys


def parse_key_names(raw: str) -> dict[str, str]:
    """'key-3f2a9c1b=alice,key-9d8e7f6a=site-app' -> {fingerprint: name}."""
    names: dict[str, str] = {}
    for number, entry in enumerate((e.strip() for e in raw.split(",")), start=1):
        if not entry:
            continue
        fingerprint, sep, name = (part.strip() for part in entry.partition("="))
        if not sep or not fingerprint or not name:
            raise ApiKeysError(
                f"LTAA_API_KEY_NAMES entry {number} is not FINGERPRINT=NAME "
                "(e.g. key-3f2a9c1b=alice; print a fingerprint with: ltaa key-name KEY)"
            )
        if len(name) > MAX_KEY_NAME_CHARS or not name.isprintable():
            raise ApiKeysError(
                f"LTAA_API_KEY_NAMES entry {number}: a name is 1-{MAX_KEY_NAME_CHARS} "
                "printable characters"
            )
        if fingerprint in names:
            raise ApiKeysError(f"LTAA_API_KEY_NAMES entry {number} repeats a fingerprint")
        names[fingerprint] = name
    return names


def is_loopback(host: str) -> bool:
    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False  # a hostname other than localhost may resolve to anything


def check_bind(settings: Settings, keyring: KeyRing) -> None:
    if keyring.open and not is_loopback(settings.host):
        raise InsecureBindError(
            f"refusing to start: the server would listen on {settings.host} (LTAA_HOST / "
            "HOST), beyond this machine, with no API keys configured, so anyone who can reach "
            "it could read every run and trace. Set LTAA_API_KEYS='KEY:supervisor,KEY:client' "
            f"(README, 'Access control'; {KEY_HINT}), or listen on 127.0.0.1."
        )
