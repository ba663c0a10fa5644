"""Server settings, read from FOIL_* environment variables (or given directly by `foil serve` and the tests)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


class TransportLimits(BaseSettings):
    """What the HTTP server accepts (app.web.transport), from the same FOIL_* variables; `foil serve` applies them,
    and so does uvicorn's command line with `--http app.web.transport:SurveyHttpProtocol`."""

    model_config = SettingsConfigDict(env_prefix="FOIL_", extra="ignore")

    # The request line and header fields together; a browser sends 1-2 KB here (the session cookie is small).
    max_header_bytes: int = Field(default=16 * 1024, ge=1024)
    max_headers: int = Field(default=64, ge=8)
    # From the first byte of a request (or the connection's opening) to its last: a form is at most
    # FOIL_MAX_BODY_BYTES, which even a poor mobile connection sends in a few seconds.
    request_timeout_s: float = Field(default=20.0, gt=0, le=3600, allow_inf_nan=False)
    # How long a connection stays open between requests (uvicorn's timeout_keep_alive): long enough for a page's
    # stylesheet, script and clip requests, not for the minutes a participant spends on a page.
    keep_alive_s: int = Field(default=5, ge=1, le=300)


class ServerSettings(BaseSettings):
    """What one survey server runs with: its bundle, study and database, the admin password and the limits of
    sessions, logins and arrivals (docs/survey.md lists them as FOIL_* variables)."""

    model_config = SettingsConfigDict(env_prefix="FOIL_", extra="ignore")

    bundle_dir: Path
    study_file: Path | None = None  # default: study.toml inside the bundle
    database_url: str = "sqlite:///foil.sqlite3"
    # Without it, the admin pages are off. No default on purpose.
    admin_password: SecretStr | None = None
    # Signs the session cookies. Without it, one is generated once and kept in the database.
    secret_key: SecretStr | None = None
    cookie_secure: bool = False  # set when serving over HTTPS (required for SameSite=None)
    cookie_samesite: Literal["lax", "strict", "none"] = "lax"
    session_max_age_s: int = 7 * 24 * 3600
    max_body_bytes: int = Field(default=64 * 1024, ge=1024)
    # Who may show the pages in a frame (Content-Security-Policy frame-ancestors); none by default.
    frame_ancestors: str = "'none'"
    # SQLite only: "full" commits survive a power loss or an operating-system crash, "normal" only a crash of the
    # server process (docs/survey.md).
    sqlite_synchronous: Literal["normal", "full"] = "full"
    access_log: bool = True  # uvicorn's line per request, from `foil serve`
    # Admin password guessing: after this many wrong passwords (per client, an IPv4 address or an IPv6 /64; from
    # everyone together) each attempt waits a delay that starts at login_delay_s and doubles with every failure, up
    # to login_max_delay_s.
    login_free_attempts: int = Field(default=5, ge=1)
    login_free_attempts_overall: int = Field(default=100, ge=1)
    login_delay_s: float = Field(default=1.0, gt=0, allow_inf_nan=False)
    login_max_delay_s: float = Field(default=900.0, gt=0, allow_inf_nan=False)
    # New participants per client address (a lab behind one address included): `arrivals_burst` at once, then
    # `arrivals_per_minute`; beyond that the consent page answers 429 with the seconds to wait.
    arrivals_burst: int = Field(default=100, ge=1)
    arrivals_per_minute: float = Field(default=60.0, gt=0, allow_inf_nan=False)
    # Host names the server answers to (Starlette's TrustedHostMiddleware; other Host headers get 400), as a JSON
    # list: FOIL_ALLOWED_HOSTS='["survey.example.org"]'. No reply is built from the Host header in any case.
    allowed_hosts: list[str] = ["*"]

    @model_validator(mode="after")
    def _sane(self) -> ServerSettings:
        if self.admin_password is not None and len(self.admin_password.get_secret_value()) < 8:
            raise ValueError("FOIL_ADMIN_PASSWORD must be at least 8 characters long")
        if self.cookie_samesite == "none" and not self.cookie_secure:
            raise ValueError("FOIL_COOKIE_SAMESITE=none needs FOIL_COOKIE_SECURE=1 (browsers refuse it otherwise)")
        return self

    def study_path(self) -> Path:
        return self.study_file or self.bundle_dir / "study.toml"
