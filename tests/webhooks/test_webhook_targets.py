"""SSRF checks and Standard Webhooks signing, as pure functions."""

from __future__ import annotations

import ipaddress
from datetime import UTC, datetime

import pytest
from standardwebhooks import Webhook

from app.domain.errors import DomainError
from app.webhooks import signing
from app.webhooks.secret_box import new_secret
from app.webhooks.targets import (
    Resolver,
    TargetRefused,
    check_subscription_url,
    resolve_target,
    static_resolver,
)


def answers(*addresses: str) -> Resolver:
    return lambda host, port: list(addresses)


def test_the_request_goes_to_the_checked_address_with_the_host_kept() -> None:
    target = resolve_target(
        "https://hooks.example:8443/in?x=1", resolver=answers("93.184.216.34"), allow_private=False
    )
    assert target.url == "https://93.184.216.34:8443/in?x=1"
    assert target.host_header == "hooks.example:8443"
    assert target.server_name == "hooks.example"  # TLS SNI and certificate name
    v6 = resolve_target(
        "http://hooks.example/in", resolver=answers("2606:4700::1"), allow_private=False
    )
    assert v6.url == "http://[2606:4700::1]/in" and v6.server_name is None


@pytest.mark.parametrize(
    "addresses",
    [("10.0.0.1",), ("93.184.216.34", "127.0.0.1"), ("::ffff:192.168.0.1",), ("fe80::1%eth0",)],
)
def test_any_non_global_answer_refuses_the_delivery(addresses: tuple[str, ...]) -> None:
    with pytest.raises(TargetRefused, match="not a global address"):
        resolve_target("http://hooks.example/", resolver=answers(*addresses), allow_private=False)
    allowed = resolve_target(
        "http://hooks.example/", resolver=answers(*addresses), allow_private=True
    )
    assert ipaddress.ip_address(allowed.address) == ipaddress.ip_address(addresses[0].split("%")[0])


def test_unresolvable_is_refused_with_the_reason() -> None:
    def fails(host: str, port: int) -> list[str]:
        raise OSError("Name or service not known")

    with pytest.raises(TargetRefused, match=r"cannot resolve hooks\.example"):
        resolve_target("http://hooks.example/", resolver=fails, allow_private=False)


def test_static_resolver_answers_its_names_only() -> None:
    resolve = static_resolver("a.test=10.0.0.1,a.test=10.0.0.2", fallback=lambda h, p: ["1.1.1.1"])
    assert resolve("A.test", 80) == ["10.0.0.1", "10.0.0.2"]
    assert resolve("b.test", 80) == ["1.1.1.1"]


def test_global_literals_and_names_pass_at_creation() -> None:
    assert check_subscription_url("https://93.184.216.34/x", allow_private=False)
    assert check_subscription_url("https://hooks.example/x", allow_private=False)
    assert check_subscription_url("http://10.0.0.1/x", allow_private=True)
    with pytest.raises(DomainError) as exc:
        check_subscription_url("http://100.64.0.1/x", allow_private=False)  # carrier NAT
    assert exc.value.field == "url"


def test_signatures_verify_with_the_standardwebhooks_library() -> None:
    old, new = new_secret(), new_secret()
    body = b'{"type":"run.created","timestamp":"2026-01-01T00:00:00.000Z","data":{"run_id":"x"}}'
    now = int(datetime.now(UTC).timestamp())
    headers = signing.headers([new, old], "msg_1", now, body)
    assert headers["webhook-signature"].count("v1,") == 2
    for secret in (old, new):
        assert Webhook(secret).verify(body, headers)["data"]["run_id"] == "x"
    with pytest.raises(Exception, match="too old"):
        Webhook(new).verify(body, signing.headers([new], "msg_1", now - 3600, body))
    tampered = {**headers, "webhook-id": "msg_2"}
    with pytest.raises(Exception, match="No matching signature"):
        Webhook(new).verify(body, tampered)
