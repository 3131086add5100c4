"""HTTPS to a pinned address: the connection goes to the checked IP while TLS speaks to the
URL's host name (SNI and certificate check), against a real TLS server on loopback."""

from __future__ import annotations

import datetime as dt
import ssl
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import httpx
import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from app.webhooks.sender import send
from app.webhooks.status import AttemptOutcome

NAME = "hooks.site.example"


def _cert(
    subject: str, key: ec.EllipticCurvePrivateKey, issuer: x509.Name, signer: Any, ca: bool
) -> x509.Certificate:
    now = dt.datetime.now(dt.UTC)
    builder = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, subject)]))
        .issuer_name(issuer)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(hours=1))
        .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True)
    )
    if not ca:
        builder = builder.add_extension(
            x509.SubjectAlternativeName([x509.DNSName(subject)]), critical=False
        )
    return builder.sign(signer, hashes.SHA256())


@pytest.fixture
def tls_receiver(tmp_path: Path) -> Iterator[tuple[int, ssl.SSLContext, list[str | None]]]:
    """A TLS server on 127.0.0.1 whose certificate names NAME only; it records the SNI."""
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "test CA")])
    ca = _cert("test CA", ca_key, ca_name, ca_key, ca=True)
    leaf_key = ec.generate_private_key(ec.SECP256R1())
    leaf = _cert(NAME, leaf_key, ca_name, ca_key, ca=False)
    (tmp_path / "leaf.pem").write_bytes(leaf.public_bytes(serialization.Encoding.PEM))
    (tmp_path / "leaf.key").write_bytes(
        leaf_key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    server_names: list[str | None] = []
    server_ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    server_ctx.load_cert_chain(tmp_path / "leaf.pem", tmp_path / "leaf.key")
    server_ctx.sni_callback = lambda sock, name, ctx: server_names.append(name)

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self) -> None:
            self.rfile.read(int(self.headers.get("content-length") or 0))
            self.send_response(204)
            self.send_header("content-length", "0")
            self.end_headers()

        def log_message(self, *args: Any) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    server.socket = server_ctx.wrap_socket(server.socket, server_side=True)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05})
    thread.start()
    client_ctx = ssl.create_default_context(
        cadata=ca.public_bytes(serialization.Encoding.PEM).decode()
    )
    try:
        yield int(server.server_address[1]), client_ctx, server_names
    finally:
        server.shutdown()
        server.server_close()
        thread.join()


def _send(port: int, ctx: ssl.SSLContext, host: str) -> Any:
    with httpx.Client(verify=ctx, trust_env=False, follow_redirects=False) as client:
        return send(
            client,
            url=f"https://{host}:{port}/hooks",
            body=b"{}",
            headers={"webhook-id": "msg_1"},
            resolver=lambda h, p: ["127.0.0.1"],
            allow_private=True,
            max_response_bytes=1024,
            timeout_s=5,
        )


def test_https_connects_to_the_checked_address_and_verifies_the_host_name(
    tls_receiver: tuple[int, ssl.SSLContext, list[str | None]],
) -> None:
    port, ctx, server_names = tls_receiver
    result = _send(port, ctx, NAME)
    assert result.outcome is AttemptOutcome.DELIVERED, result.error
    assert server_names == [NAME]  # SNI carried the name, not the address


def test_a_certificate_for_another_name_fails_the_attempt(
    tls_receiver: tuple[int, ssl.SSLContext, list[str | None]],
) -> None:
    port, ctx, _ = tls_receiver
    result = _send(port, ctx, "other.site.example")  # resolves to the same address
    assert result.outcome is AttemptOutcome.NETWORK_ERROR
    assert "CERTIFICATE_VERIFY_FAILED" in (result.error or "")
