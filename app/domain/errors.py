"""Errors the domain raises; the API turns them into 4xx JSON naming the field."""

from __future__ import annotations

IDEMPOTENCY_HEADER = "Idempotency-Key"


class DomainError(ValueError):
    """A request that cannot be served as sent. `field` is a dotted path into the request."""

    status_code = 422
    location = "body"  # which part of the HTTP request `field` points into

    def __init__(self, field: str, message: str, *, code: str = "invalid") -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message
        self.code = code


def refuse_nul(field: str, value: str | None) -> None:
    """PostgreSQL refuses a NUL in any text value: refuse it up front, naming the field, for
    callers that reach a service past the API's body models (the console's forms)."""
    if value is not None and "\x00" in value:
        raise DomainError(
            field, "must not contain a NUL character (\\u0000); remove it", code="nul_character"
        )


class NotFoundError(DomainError):
    """No such thing as the path names (404); the message says where to list them."""

    status_code = 404
    location = "path"

    def __init__(self, field: str, message: str) -> None:
        super().__init__(field, message, code="not_found")


class StateConflictError(DomainError):
    """The thing named in the path is in a state that forbids the action (409). One shape
    for runs and webhook deliveries alike, so clients read every such conflict the same
    way."""

    status_code = 409
    location = "path"

    def __init__(self, field: str, message: str) -> None:
        super().__init__(field, message, code="conflict")


class IdempotencyKeyReusedError(DomainError):
    """An Idempotency-Key sent again with another request (409). One class for runs, reports,
    reviews, sign-offs and webhooks alike: `what` names what the key did the first time
    ("it created webhook 'w-1'"), and the message says how to go on."""

    status_code = 409
    location = "header"

    def __init__(
        self, what: str, *, sent: str = "request", resend: str = "the original request"
    ) -> None:
        super().__init__(
            IDEMPOTENCY_HEADER,
            f"this {IDEMPOTENCY_HEADER} was already used with a different {sent} ({what}); "
            f"send a new key for a new request, or resend {resend}",
            code="idempotency_key_reused",
        )

    @classmethod
    def for_run(cls, run_id: str) -> IdempotencyKeyReusedError:
        """The key created (or wrote for) run `run_id`; resending the first body gets it."""
        return cls(
            f"it created run '{run_id}'",
            sent="request body",
            resend="the original body to get that run",
        )


class InfeasibleCapError(DomainError):
    """No allocation can keep every robot's load inside the workload cap.

    `suggested_max_deviation`, when known, is the smallest cap that admits a completion
    (given the pins); `field` is `pinned` when the pins, not the counts, break the cap.
    """

    def __init__(
        self,
        message: str,
        *,
        field: str = "max_deviation",
        suggested_max_deviation: float | None = None,
    ) -> None:
        super().__init__(field, message, code="infeasible_cap")
        self.suggested_max_deviation = suggested_max_deviation


class TooLargeError(DomainError):
    """The request is bigger than a solver (or the service) accepts."""


# -- run-level errors (the run's life, its lookup and its archive) ---------------------------


class RunNotFoundError(NotFoundError):
    def __init__(self, run_id: str) -> None:
        super().__init__("run_id", f"no run with id '{run_id}'; list runs with GET /runs")
        self.run_id = run_id  # the API answers 410 instead when this id was archived


class RunArchivedError(DomainError):
    status_code = 410
    location = "path"

    def __init__(self, run_id: str, archive_file: str) -> None:
        super().__init__(
            "run_id",
            f"run '{run_id}' was archived to '{archive_file}' (in the server's archive "
            "directory); its record is that file, which scripts/check_trace.py verifies",
            code="archived",
        )


class RunStateConflictError(StateConflictError):
    def __init__(self, run_id: str, status: str, action: str, hint: str) -> None:
        super().__init__("run_id", f"run '{run_id}' is {status}; cannot {action}. {hint}")
