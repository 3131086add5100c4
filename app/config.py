"""Service settings, read from `LTAA_*` environment variables (pydantic-settings)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import (
    AliasChoices,
    Field,
    SecretStr,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

# MPXJ writes 10,000 activities as 23 MB of MSPDI (3 MB of XER): docs/exchange.md.
DEFAULT_IMPORT_MAX_BYTES = 20 * 1024 * 1024
DEFAULT_MAX_BODY_BYTES = 10 * 1024 * 1024  # 10,000 tasks with TEACh metadata fit comfortably
# Seconds between a webhook's failed attempts (8 attempts over ~27.6 h, as Svix does): a
# receiver down for a day still gets every event. Jitter of +-20% is added to each.
DEFAULT_WEBHOOK_RETRY_DELAYS_S = (5.0, 300.0, 1800.0, 7200.0, 18000.0, 36000.0, 36000.0)


class Settings(BaseSettings):
    """Every knob of the service. Paths left unset are derived from `data_dir`."""

    model_config = SettingsConfigDict(
        env_prefix="LTAA_",
        # Tests and the CLI build Settings(field=...) directly, aliases notwithstanding.
        populate_by_name=True,
        extra="ignore",
    )

    data_dir: Path = Path("data")
    database_url: str | None = Field(
        None, description="SQLAlchemy URL; default sqlite:///{data_dir}/ltaa.db"
    )
    checkpoint_path: Path | None = Field(
        None, description="LangGraph SQLite checkpointer; default {data_dir}/checkpoints.sqlite"
    )
    host: str = "127.0.0.1"
    port: int = Field(8000, ge=1, le=65535)

    max_concurrent_runs: int = Field(4, ge=1)
    auto_resume: bool = True
    default_reasoner: str = "rules"
    default_model: str = "claude-sonnet-4-6"

    # Scale-out (only with a postgresql:// database_url; SQLite keeps one process, no
    # leases). A run belongs to the process holding its lease; the lease is renewed every
    # lease_s / 3, so a process must be unresponsive for lease_s before another takes over.
    lease_s: float = Field(30.0, gt=0, description="How long a run's lease lasts unrenewed")
    claim_poll_s: float = Field(
        2.0, gt=0, description="How often a process looks for queued runs and expired leases"
    )
    worker_name: str | None = Field(
        None,
        max_length=64,
        description="Label of this process in leases and run events; default hostname",
    )

    # The fleet bridge (docs/fleet.md): VDA 5050 orders out, robot state in, over MQTT. Off
    # (no broker needed) unless mqtt_url is set.
    mqtt_url: str | None = Field(
        None,
        pattern=r"^mqtts?://[^\s/:]+(:\d+)?/?$",
        description="e.g. mqtt://127.0.0.1:1883; unset: no fleet bridge",
    )
    mqtt_interface: str = Field(
        "uagv", pattern=r"^[A-Za-z0-9_-]+$", description="The first level of every topic"
    )
    mqtt_manufacturer: str = Field(
        "ltaa-sim",
        pattern=r"^[^/#+\s]+$",
        description="The manufacturer a site's robots are addressed under (their serial "
        "number is the robot's name)",
    )
    mqtt_sites: str = Field(
        "default",
        description="Comma-separated sites whose runs are sent to the robots; '*' for all",
    )
    mqtt_client_id: str | None = Field(
        None,
        max_length=58,  # and "-echo": 63
        description="The MQTT client id the active bridge connects under (its echo session: "
        "{id}-echo); default the one the store's bridge last used, first "
        "ltaa-{hostname}-{a digest of the database URL}",
    )
    # One active bridge per database (docs/fleet.md#one-bridge-per-database): a lease by the
    # database clock, renewed every mqtt_lease_s / 4; a standby takes over within it.
    mqtt_lease_s: float = Field(
        10.0, gt=0, description="How long the active fleet bridge's lease lasts unrenewed"
    )

    # The Anthropic SDK's own variable is honoured so an existing key just works.
    anthropic_api_key: SecretStr | None = Field(
        None, validation_alias=AliasChoices("LTAA_ANTHROPIC_API_KEY", "ANTHROPIC_API_KEY")
    )
    anthropic_base_url: str | None = Field(
        None, validation_alias=AliasChoices("LTAA_ANTHROPIC_BASE_URL", "ANTHROPIC_BASE_URL")
    )
    anthropic_timeout_s: float = Field(60.0, gt=0)
    anthropic_max_transport_retries: int = Field(3, ge=0)
    # The `openai` reasoner: an OpenAI-compatible Chat Completions server (vLLM, Ollama,
    # llama.cpp, OpenAI). Only these LTAA_ names are read, never the SDK's OPENAI_* ones:
    # site data goes to the server the operator named here, or nowhere.
    openai_base_url: str | None = Field(
        None,
        pattern=r"^https?://\S+$",
        description="e.g. http://127.0.0.1:8001/v1 (vLLM), http://127.0.0.1:11434/v1 (Ollama)",
    )
    openai_api_key: SecretStr | None = Field(None, description="Optional for local servers")
    openai_model: str | None = Field(None, min_length=1, description="e.g. Qwen/Qwen3-8B")
    openai_timeout_s: float = Field(60.0, gt=0)
    openai_max_transport_retries: int = Field(3, ge=0)
    # How a run asks its model for a decision (docs/reasoners.md#structured-replies):
    # json_schema (OpenAI, vLLM, Ollama; a server that refuses it is asked in json_object),
    # json_object (llama-cpp-python's server), markdown (the paper's sections). Stored with
    # each run when it is created.
    llm_reply_format: Literal["json_schema", "json_object", "markdown"] = "json_schema"
    # Output tokens per attempt, by prompt tier 0-3 (docs/reasoners.md#bounded-cost): one
    # number for every tier, or up to four comma-separated.
    llm_max_tokens: Annotated[list[int], NoDecode] = Field(
        default_factory=lambda: [400, 400, 500, 500],
        description="Comma-separated output-token caps of tiers 0-3 (each 32-8192)",
    )
    # After this many tasks in a row ended in the rules fallback, a run asks its model no
    # more and the rule decides the rest (docs/reasoners.md#bounded-cost); 0: never.
    llm_give_up_after: int = Field(3, ge=0, le=10_000)
    # LLM tokens (input + output) a run may spend when its request names no token_budget;
    # then its remaining tasks go to the offline rules reasoner. None: no limit.
    run_token_budget: int | None = Field(None, ge=1)
    # Site estimates (docs/estimates.md#the-model): how many pseudo-observations the configured rate
    # (and duration) weighs as the prior of each posterior.
    prior_strength: float = Field(10.0, gt=0, le=1_000_000, allow_inf_nan=False)

    # Test-only seam: every durable run holds at `<task index>:<node>:<before|after>` (any
    # of the nine nodes; see app.graph.pause), logging where it holds, so an end-to-end test
    # can SIGKILL or SIGTERM the server at a known point. Warned about at start-up.
    test_pause: str | None = Field(None, pattern=r"^[0-9]+:[a-z_]+:(before|after)$")

    # Test-only seam: the graph version this process claims (app.graph.version derives it
    # from the code), so a test can interrupt a run under one version and restart the
    # server under another. Warned about at start-up.
    test_graph_version: str | None = Field(None, min_length=1, max_length=64)

    # Signed chain heads (app.audit.signing): an Ed25519 private key in PEM (`ltaa keygen`
    # writes one); and a directory of retired public keys (*.pem), kept so that runs signed
    # before a rotation still verify.
    signing_key_file: Path | None = None
    # Where POST /admin/backup may write (a supervisor key must not write anywhere the
    # server can); default {data_dir}/backups.
    backup_dir: Path | None = None
    # Where archived runs' JSON-lines files go; default {data_dir}/archive.
    archive_dir: Path | None = None
    retired_public_keys_dir: Path | None = None

    max_body_bytes: int = Field(DEFAULT_MAX_BODY_BYTES, ge=1)
    # POST /schedules/import: a site's MS Project or P6 file (docs/exchange.md); larger than
    # a JSON request may be, as the files carry much the draft leaves out.
    import_max_bytes: int = Field(DEFAULT_IMPORT_MAX_BYTES, ge=1)

    # "KEY:ROLE,KEY:ROLE" (roles: client, supervisor), parsed by app.http.auth. A SecretStr so
    # repr(), model_dump() and validation errors never show a key.
    api_keys: SecretStr | None = None
    # Non-secret names of the keys above, by fingerprint: "key-3f2a9c1b=alice,..." (see
    # app.http.auth). Unnamed keys are called by their fingerprint.
    api_key_names: str | None = None
    log_format: Literal["json", "text"] = "json"
    log_level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = "INFO"
    # GET /runs/{id}/events polls the app tables at this interval (works across processes).
    events_poll_s: float = Field(0.1, gt=0, le=10)
    # A stream ends after this long even if the run has not; EventSource reconnects with
    # Last-Event-ID and misses nothing. (A shutdown ends every stream at once.)
    events_max_stream_s: float = Field(300.0, gt=0)

    # A supervisor console session (app.console) ends this long after sign-in: one shift.
    console_session_s: float = Field(8 * 3600.0, gt=0, le=30 * 24 * 3600.0)

    # -- webhooks (docs/webhooks.md) -----------------------------------------------------
    # Fernet keys (comma-separated; the first encrypts, all decrypt) protecting webhook
    # secrets at rest. Unset: a key file generated in data_dir on first use (one process);
    # processes sharing a PostgreSQL database must share this setting.
    secret_key: SecretStr | None = None
    # Deliver to private, loopback, link-local... addresses (tests; site LANs).
    webhook_allow_private: bool = False
    webhook_retry_delays_s: Annotated[list[float], NoDecode] = Field(
        default_factory=lambda: list(DEFAULT_WEBHOOK_RETRY_DELAYS_S),
        description="Comma-separated seconds between attempts; then the delivery fails",
    )
    webhook_timeout_s: float = Field(10.0, gt=0, le=60)
    webhook_max_response_bytes: int = Field(64 * 1024, ge=0)
    webhook_poll_s: float = Field(0.5, gt=0, le=60)
    # How long a process holds a claimed delivery; past it, another process may retry it
    # (its owner died). Longer than the timeout, so a live process always finishes first.
    webhook_claim_s: float = Field(60.0, gt=0)
    webhook_concurrency: int = Field(4, ge=1, le=64)
    webhook_secret_grace_s: float = Field(
        86400.0, ge=0, description="How long a rotated-out secret keeps signing"
    )
    # Ops/test: off, deliveries wait in the outbox (a restart with it on sends them).
    webhook_dispatch: bool = True
    # Test-only resolver seam: "host=ip,host=ip" answers DNS for these names.
    test_webhook_resolve: str | None = None

    @field_validator("webhook_retry_delays_s", mode="before")
    @classmethod
    def _delays(cls, value: object) -> object:
        if isinstance(value, str):
            return [part.strip() for part in value.split(",") if part.strip()]
        return value

    @field_validator("webhook_retry_delays_s")
    @classmethod
    def _non_negative(cls, value: list[float]) -> list[float]:
        if any(delay < 0 for delay in value):
            raise ValueError("retry delays must be >= 0 seconds")
        return value

    @field_validator("llm_max_tokens", mode="before")
    @classmethod
    def _caps(cls, value: object) -> object:
        if isinstance(value, str):
            return [part.strip() for part in value.split(",") if part.strip()]
        return [value] if isinstance(value, int) else value

    @field_validator("llm_max_tokens")
    @classmethod
    def _caps_in_range(cls, value: list[int]) -> list[int]:
        if not 1 <= len(value) <= 4:
            raise ValueError(
                f"give one output-token cap for every tier or one per tier 0-3, not {len(value)}"
            )
        wrong = [cap for cap in value if not 32 <= cap <= 8192]
        if wrong:
            raise ValueError(
                f"each output-token cap must be 32-8192 (a decision needs a few hundred), "
                f"not {wrong[0]}"
            )
        return value

    @field_validator("log_level", mode="before")
    @classmethod
    def _upper(cls, value: object) -> object:
        return value.upper() if isinstance(value, str) else value

    @field_validator("log_format", mode="before")
    @classmethod
    def _lower(cls, value: object) -> object:
        return value.lower() if isinstance(value, str) else value

    @model_validator(mode="after")
    def _derive_paths(self) -> Settings:
        # Filled in place so model_dump() and logs show the paths actually used.
        self.database_url = self.db_url
        self.checkpoint_path = self.checkpoint_file
        return self

    @property
    def db_url(self) -> str:
        """`database_url`, typed as a plain str (derived from data_dir when unset)."""
        return self.database_url or f"sqlite:///{self.data_dir.as_posix()}/ltaa.db"

    @property
    def archive_root(self) -> Path:
        return self.archive_dir or self.data_dir / "archive"

    @property
    def backup_root(self) -> Path:
        return self.backup_dir or self.data_dir / "backups"

    @property
    def checkpoint_file(self) -> Path:
        """`checkpoint_path`, typed as a plain Path (derived from data_dir when unset)."""
        return self.checkpoint_path or self.data_dir / "checkpoints.sqlite"


class SettingsError(ValueError):
    """A setting the service refuses to start with, named as it is set (LTAA_...)."""


def get_settings() -> Settings:
    """Read settings from the environment now (deliberately uncached: tests change the env).
    A value out of range stops the start with one sentence per setting at fault."""
    try:
        return Settings()
    except ValidationError as exc:
        raise SettingsError(refusal(exc)) from None


def refusal(exc: ValidationError) -> str:
    """Each setting at fault as its variable, what it was set to and why it is refused."""
    lines = []
    for error in exc.errors():
        name = str(error["loc"][0]) if error["loc"] else "settings"
        shown = "" if "secret" in name or "key" in name else f"={error.get('input')!s:.60}"
        message = str(error["msg"]).removeprefix("Value error, ")
        lines.append(f"LTAA_{name.upper()}{shown} is refused: {message}.")
    return "the service cannot start: " + " ".join(lines)
