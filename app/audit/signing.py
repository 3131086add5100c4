"""Signed chain heads: Ed25519 signatures over a run's chain heads, verifiable with the
public key alone.

A hash chain shows that a record changed only to someone who recorded its heads; anyone
who can write the database and read the code can recompute every link after an edit.
With a server signing key, the heads are signed when a run completes (and at each
sign-off once reviews exist): a rewrite then needs the private key to be consistent, and
verifying needs no secret (an HMAC would give every verifier the power to forge). Retired
public keys are kept so runs signed before a key rotation still verify.

Without a key nothing is signed, and the record is tamper-evident only against writers who
do not know the chain scheme (documented in docs/operations.md).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey
from sqlalchemy.orm import Session

from app.audit.heads import chain_heads, geneses
from app.config import Settings
from app.store import chain
from app.store.models import Run, RunSignature

ALGORITHM = "Ed25519"
PAYLOAD_FORMAT = "ltaa-signed-heads/v1"


class SigningKeyError(ValueError):
    """A key file that cannot be used; the message names it."""


def key_id(public: Ed25519PublicKey) -> str:
    raw = public.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    return hashlib.sha256(raw).hexdigest()[:16]


def public_pem(public: Ed25519PublicKey) -> str:
    return public.public_bytes(
        serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo
    ).decode()


def _load_private(path: Path) -> Ed25519PrivateKey:
    try:
        key = serialization.load_pem_private_key(path.read_bytes(), password=None)
    except (OSError, ValueError, TypeError) as exc:
        raise SigningKeyError(f"cannot read the signing key {path}: {exc}") from None
    if not isinstance(key, Ed25519PrivateKey):
        raise SigningKeyError(f"{path} is not an Ed25519 private key")
    return key


def _load_public(path: Path) -> Ed25519PublicKey:
    try:
        key = serialization.load_pem_public_key(path.read_bytes())
    except (OSError, ValueError) as exc:
        raise SigningKeyError(f"cannot read the retired public key {path}: {exc}") from None
    if not isinstance(key, Ed25519PublicKey):
        raise SigningKeyError(f"{path} is not an Ed25519 public key")
    return key


@dataclass
class SigningKeys:
    private: Ed25519PrivateKey | None = None
    public: dict[str, Ed25519PublicKey] = field(default_factory=dict)  # key id -> key

    @property
    def current_id(self) -> str | None:
        return key_id(self.private.public_key()) if self.private is not None else None

    @classmethod
    def from_settings(cls, settings: Settings) -> SigningKeys:
        keys = cls()
        if settings.retired_public_keys_dir is not None:
            for path in sorted(Path(settings.retired_public_keys_dir).glob("*.pem")):
                public = _load_public(path)
                keys.public[key_id(public)] = public
        if settings.signing_key_file is not None:
            keys.private = _load_private(Path(settings.signing_key_file))
            public = keys.private.public_key()
            keys.public[key_id(public)] = public
        return keys


def generate_key_file(path: Path) -> str:
    """A new Ed25519 private key in PEM (mode 0600); returns its key id."""
    key = Ed25519PrivateKey.generate()
    pem = key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    path.touch(mode=0o600, exist_ok=False)
    path.write_bytes(pem)
    return key_id(key.public_key())


def payload_bytes(payload: dict[str, Any]) -> bytes:
    return chain.canonical_json(payload).encode("utf-8")


def heads_payload(session: Session, run: Run, reason: str) -> dict[str, Any]:
    """What is signed: the run, its scheme, both geneses and both heads with their counts."""
    heads = chain_heads(session, run.id)
    return {
        "format": PAYLOAD_FORMAT,
        "run_id": run.id,
        "reason": reason,
        "chain_scheme": run.chain_scheme or chain.SCHEME,
        "genesis": geneses(run),
        "heads": heads.as_dict(),
        "decisions": heads.decisions,
        "events": heads.events,
    }


def sign_in(session: Session, keys: SigningKeys, run: Run, reason: str) -> RunSignature | None:
    """Sign the run's heads as this transaction leaves them, in it: whatever it commits
    (a run's completed event, a sign-off) is never seen unsigned, even across a crash."""
    if keys.private is None:
        return None
    session.flush()  # the heads read below include what this transaction has added
    payload = heads_payload(session, run, reason)
    row = RunSignature(
        run_id=run.id,
        reason=reason,
        key_id=str(keys.current_id),
        payload=payload,
        signature=keys.private.sign(payload_bytes(payload)).hex(),
    )
    session.add(row)
    return row


@dataclass(frozen=True)
class SignatureCheck:
    key_id: str
    reason: str
    valid: bool
    problem: str | None


def check_signature(
    keys: SigningKeys,
    row_key_id: str,
    payload: dict[str, Any],
    signature_hex: str,
    heads: dict[str, str | None],
    geneses: dict[str, str],
) -> SignatureCheck:
    """The signature is the key's over the payload, and the payload names the heads and
    geneses recomputed from the rows."""
    reason = str(payload.get("reason", ""))
    public = keys.public.get(row_key_id)
    if public is None:
        return SignatureCheck(row_key_id, reason, False, f"unknown signing key {row_key_id}")
    try:
        public.verify(bytes.fromhex(signature_hex), payload_bytes(payload))
    except (InvalidSignature, ValueError):
        return SignatureCheck(
            row_key_id, reason, False, "bad signature: the signed heads were altered"
        )
    if payload.get("heads") != heads or payload.get("genesis") != geneses:
        return SignatureCheck(
            row_key_id,
            reason,
            False,
            "the record's chain heads differ from the signed ones: rewritten after signing",
        )
    return SignatureCheck(row_key_id, reason, True, None)
