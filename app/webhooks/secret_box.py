"""Webhook secrets: generated here, stored encrypted with the server key (MultiFernet).

`LTAA_SECRET_KEY` holds one or more Fernet keys, comma-separated: the first encrypts, every
one decrypts, so a key is rotated by putting a new one first and dropping the old one once
`rotate_all` re-encrypted the rows. Without the setting, a key is generated on first use
in `{data_dir}/webhook-secret.key` (mode 0600); a database backup without that file (or
the setting) holds no usable secret.
"""

from __future__ import annotations

import base64
import os
import secrets
import threading
from collections.abc import Callable
from pathlib import Path

from cryptography.fernet import Fernet, InvalidToken, MultiFernet

from app.webhooks.errors import SecretKeyError

SECRET_PREFIX = "whsec_"
SECRET_BYTES = 32
KEY_FILE_NAME = "webhook-secret.key"


def new_secret() -> str:
    """A Standard Webhooks secret: `whsec_` + base64 of 32 random bytes."""
    return SECRET_PREFIX + base64.b64encode(secrets.token_bytes(SECRET_BYTES)).decode("ascii")


def secret_bytes(secret: str) -> bytes:
    """The HMAC key: the base64 part of a `whsec_...` secret, decoded."""
    return base64.b64decode(secret.removeprefix(SECRET_PREFIX))


class SecretBox:
    """Encrypts and decrypts webhook secrets. Keys from the setting are checked at once
    (a bad key stops the start-up); the key file is read or created at first use."""

    def __init__(self, load_keys: Callable[[], list[bytes]]) -> None:
        self._load_keys = load_keys
        self._lock = threading.Lock()
        self._cached: MultiFernet | None = None

    @classmethod
    def from_setting(cls, raw: str | None, data_dir: Path) -> SecretBox:
        if raw is not None and raw.strip():
            keys = [k.strip().encode("ascii") for k in raw.split(",") if k.strip()]
            box = cls(lambda: keys)
            box._cached = _multi(keys)  # a bad key fails here, at start-up
            return box
        return cls(lambda: [_key_file(data_dir / KEY_FILE_NAME)])

    @property
    def _fernet(self) -> MultiFernet:
        with self._lock:
            if self._cached is None:
                self._cached = _multi(self._load_keys())
            return self._cached

    def encrypt(self, secret: str) -> str:
        return self._fernet.encrypt(secret.encode("utf-8")).decode("ascii")

    def decrypt(self, ciphertext: str) -> str:
        try:
            return self._fernet.decrypt(ciphertext.encode("ascii")).decode("utf-8")
        except InvalidToken:
            raise SecretKeyError(
                "a webhook secret cannot be decrypted with this server's key: "
                "LTAA_SECRET_KEY (or the key file) differs from the one that encrypted it"
            ) from None

    def rotate(self, ciphertext: str) -> str:
        """Re-encrypt under the first key (after a server key rotation)."""
        try:
            return self._fernet.rotate(ciphertext.encode("ascii")).decode("ascii")
        except InvalidToken:
            raise SecretKeyError(
                "a webhook secret cannot be decrypted with any key of LTAA_SECRET_KEY; "
                "keep the old key (after the new one) until every secret was re-encrypted"
            ) from None


def _multi(keys: list[bytes]) -> MultiFernet:
    if not keys:
        raise SecretKeyError("LTAA_SECRET_KEY holds no key")
    fernets = []
    for number, key in enumerate(keys, start=1):
        try:
            fernets.append(Fernet(key))
        except (ValueError, TypeError):
            raise SecretKeyError(
                f"LTAA_SECRET_KEY entry {number} is not a Fernet key (32 url-safe base64 "
                "bytes); generate one with: python -c 'from cryptography.fernet import "
                "Fernet; print(Fernet.generate_key().decode())'"
            ) from None
    return MultiFernet(fernets)


def _key_file(path: Path) -> bytes:
    try:
        return path.read_bytes().strip()
    except FileNotFoundError:
        pass
    path.parent.mkdir(parents=True, exist_ok=True)
    key = Fernet.generate_key()
    try:
        # O_EXCL: of two writers, one creates the file and the other reads it.
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        return path.read_bytes().strip()
    with os.fdopen(fd, "wb") as out:
        out.write(key + b"\n")
        out.flush()
        os.fsync(out.fileno())
    return key
