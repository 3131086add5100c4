"""Where a webhook may go (SSRF protection).

At creation: only absolute http(s) URLs with a host and no credentials; a literal address
or `localhost` that is not global is refused unless private targets are allowed. At each
delivery: the host is resolved once, every address it resolves to is checked, and the
request is sent to the checked address itself (the URL's host becomes the `Host` header
and the TLS server name), so a DNS answer that changes between check and connect (DNS
rebinding) cannot redirect it.
"""

from __future__ import annotations

import ipaddress
import socket
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import SplitResult, urlsplit

from app.domain.errors import DomainError

MAX_URL_CHARS = 2048
SCHEMES = ("http", "https")
ALLOW_HINT = "set LTAA_WEBHOOK_ALLOW_PRIVATE=true to deliver to private networks"

IPAddress = ipaddress.IPv4Address | ipaddress.IPv6Address
# host, port -> the addresses it resolves to (the seam tests use to fake DNS).
Resolver = Callable[[str, int], list[str]]


class TargetRefused(Exception):
    """This delivery may not be sent to where its URL points now; the message says why."""


def _bad_url(message: str, code: str = "invalid_url") -> DomainError:
    return DomainError("url", message, code=code)


def global_address(address: IPAddress) -> bool:
    # An IPv4-mapped IPv6 address (::ffff:10.0.0.1) is judged as the IPv4 address it maps.
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        address = address.ipv4_mapped
    return address.is_global and not address.is_multicast


def _literal(host: str) -> IPAddress | None:
    try:
        return ipaddress.ip_address(host)
    except ValueError:
        return None


def _is_localhost(host: str) -> bool:
    return host == "localhost" or host.endswith(".localhost")


def parse_url(url: str) -> SplitResult:
    """A subscription URL split, or a DomainError on `url` saying what is wrong."""
    if len(url) > MAX_URL_CHARS:
        raise _bad_url(f"at most {MAX_URL_CHARS} characters")
    if any(c.isspace() or ord(c) < 0x20 for c in url):
        raise _bad_url("must not contain whitespace or control characters")
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:
        raise _bad_url(f"not a valid URL: {exc}") from None
    if not parts.scheme or not parts.netloc:
        raise _bad_url("must be an absolute URL such as https://example.com/hooks")
    if parts.scheme.lower() not in SCHEMES:
        raise _bad_url(
            f"scheme '{parts.scheme}' is not allowed: use http or https", code="unsupported_scheme"
        )
    if parts.username is not None or parts.password is not None:
        raise _bad_url("must not carry credentials (user:password@); authenticate by signature")
    if not parts.hostname:
        raise _bad_url("has no host")
    if port == 0:
        raise _bad_url("port 0 is not a valid port")
    if parts.fragment:
        raise _bad_url("must not have a #fragment (it is never sent)")
    return parts


def check_subscription_url(url: str, *, allow_private: bool) -> str:
    """Validate a URL at subscription time; the URL as given."""
    parts = parse_url(url)
    host = (parts.hostname or "").lower()
    address = _literal(host)
    if allow_private:
        return url
    if _is_localhost(host):
        raise _bad_url(f"'{host}' is this machine; {ALLOW_HINT}", code="private_address")
    if address is not None and not global_address(address):
        raise _bad_url(
            f"{address} is not a global address (private, loopback, link-local or "
            f"reserved); {ALLOW_HINT}",
            code="private_address",
        )
    return url


def system_resolver(host: str, port: int) -> list[str]:
    infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    return list(dict.fromkeys(str(info[4][0]) for info in infos))


def static_resolver(table: str, fallback: Resolver = system_resolver) -> Resolver:
    """Test seam: "host=ip,host=ip" answers for those names, `fallback` for the rest."""
    answers: dict[str, list[str]] = {}
    for entry in filter(None, (e.strip() for e in table.split(","))):
        name, _, address = entry.partition("=")
        answers.setdefault(name.strip().lower(), []).append(address.strip())

    def resolve(host: str, port: int) -> list[str]:
        return answers.get(host.lower()) or fallback(host, port)

    return resolve


@dataclass(frozen=True)
class Target:
    """A checked destination: connect to `address`, speak to `host`."""

    url: str  # the URL with its host replaced by `address`
    host_header: str
    server_name: str | None  # TLS SNI and certificate name (https only)
    address: str


def resolve_target(url: str, *, resolver: Resolver, allow_private: bool) -> Target:
    parts = urlsplit(url)
    host = (parts.hostname or "").lower()
    scheme = parts.scheme.lower()
    port = parts.port or (443 if scheme == "https" else 80)
    literal = _literal(host)
    if literal is not None:
        candidates = [literal]
    else:
        try:
            resolved = resolver(host, port)
        except (OSError, UnicodeError) as exc:
            raise TargetRefused(f"cannot resolve {host}: {exc}") from None
        candidates = []
        for text in resolved:
            address = _literal(text.split("%", 1)[0])  # drop an IPv6 zone index
            if address is not None:
                candidates.append(address)
        if not candidates:
            raise TargetRefused(f"{host} resolves to no address")
    if not allow_private:
        # Every answer must be global: a name with one public and one private address
        # must not reach the private one on some later attempt.
        refused = [a for a in candidates if not global_address(a)]
        if refused or _is_localhost(host):
            shown = ", ".join(str(a) for a in refused) or str(candidates[0])
            raise TargetRefused(
                f"refused: {host} resolves to {shown}, not a global address (private, "
                f"loopback, link-local or reserved); {ALLOW_HINT}"
            )
    chosen = candidates[0]
    netloc_host = f"[{chosen}]" if chosen.version == 6 else str(chosen)
    explicit_port = f":{parts.port}" if parts.port else ""
    pinned = parts._replace(netloc=f"{netloc_host}{explicit_port}").geturl()
    host_header = parts.netloc.rsplit("@", 1)[-1]
    return Target(
        url=pinned,
        host_header=host_header,
        server_name=host if scheme == "https" and literal is None else None,
        address=str(chosen),
    )
