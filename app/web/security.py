"""Request size limits, security headers, CSRF tokens for every form (the session they live in is Starlette's
signed cookie, app.web.main), admin login throttling and admin session versions."""

from __future__ import annotations

import hmac
import ipaddress
import secrets
import threading
import time
from collections.abc import Callable
from typing import Annotated, cast
from urllib.parse import parse_qsl

from fastapi import Depends, HTTPException, Request
from sqlalchemy.orm import Session
from starlette.datastructures import FormData, UploadFile
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.store.models import ServerSetting


class BodyLimitMiddleware:
    """Refuse request bodies over `limit` bytes with 413, whether or not they announce their length."""

    def __init__(self, app: ASGIApp, limit: int):
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = dict(scope["headers"])
        declared = headers.get(b"content-length")
        if declared is None and b"transfer-encoding" not in headers:  # no body to limit
            await self.app(scope, receive, send)
            return
        if declared is not None and (not declared.isdigit() or int(declared) > self.limit):
            await _too_large(send, self.limit)
            return
        received = 0
        started = False

        async def limited_receive() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.limit:
                    raise _BodyTooLarge
            return message

        async def tracking_send(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, limited_receive, tracking_send)
        except _BodyTooLarge:
            if not started:
                await _too_large(send, self.limit)


class _BodyTooLarge(Exception):
    pass


async def _too_large(send: Send, limit: int) -> None:
    body = f"Request too large: at most {limit} bytes are accepted.".encode()
    await send(
        {
            "type": "http.response.start",
            "status": 413,
            "headers": [(b"content-type", b"text/plain; charset=utf-8"), (b"content-length", str(len(body)).encode())],
        }
    )
    await send({"type": "http.response.body", "body": body})


def security_headers(frame_ancestors: str = "'none'") -> list[tuple[bytes, bytes]]:
    """What every reply carries, the app's (SecurityHeadersMiddleware) and the HTTP server's own (app.web.transport):
    no sniffing, no framing (unless allowed), only our own scripts and media. HSTS is the reverse proxy's, which
    terminates HTTPS (docs/survey.md)."""
    policy = (
        "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; media-src 'self'; "
        f"object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors {frame_ancestors}"
    )
    headers = [
        (b"content-security-policy", policy.encode()),
        (b"x-content-type-options", b"nosniff"),
        (b"referrer-policy", b"no-referrer"),  # platform ids in our URLs must not leak to other sites
        (b"permissions-policy", b"camera=(), microphone=(), geolocation=()"),
        (b"cross-origin-opener-policy", b"same-origin"),
    ]
    if frame_ancestors == "'none'":
        headers.append((b"x-frame-options", b"DENY"))
    headers.append((b"cache-control", b"no-store"))  # pages show private state; clips set their own
    return headers


class SecurityHeadersMiddleware:
    """`security_headers` on every response of the app."""

    def __init__(self, app: ASGIApp, frame_ancestors: str):
        self.app = app
        self.headers = security_headers(frame_ancestors)
        self.names = {name for name, _ in self.headers}

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = message.get("headers", [])
                names = {name.lower() for name, _ in headers}  # a response's own headers win
                extra = (
                    self.headers
                    if names.isdisjoint(self.names)
                    else [(name, value) for name, value in self.headers if name not in names]
                )
                message = {**message, "headers": [*headers, *extra]}
            await send(message)

        await self.app(scope, receive, with_headers)


def csrf_token(request: Request) -> str:
    """The session's token, created on first use; every form carries it in a hidden field."""
    token = request.session.get("csrf")
    if not token:
        token = secrets.token_urlsafe(32)
        request.session["csrf"] = token
    return token


async def checked_form(request: Request) -> FormData:
    """The submitted form, after checking its CSRF token against the session's. Use as a dependency."""
    form = await _form(request)
    sent = form.get("csrf_token")
    expected = request.session.get("csrf")
    if not expected or not isinstance(sent, str) or not hmac.compare_digest(sent, expected):
        raise HTTPException(
            status_code=403,
            detail="This form has expired or did not come from this site. Go back, reload the page and try again "
            "(cookies must be allowed for this site).",
        )
    return form


FormDep = Annotated[FormData, Depends(checked_form)]


async def _form(request: Request) -> FormData:
    """The form's fields. Pages post URL-encoded forms, read here in one call (the body is already bounded by
    BodyLimitMiddleware); anything else goes to Starlette's parser, which takes no files here."""
    if request.headers.get("content-type", "").partition(";")[0].strip().lower() != "application/x-www-form-urlencoded":
        return await request.form(max_files=0, max_fields=MAX_FIELDS, max_part_size=MAX_FIELD_CHARS)
    try:
        fields = parse_qsl(
            (await request.body()).decode("latin-1"),
            keep_blank_values=True,
            max_num_fields=MAX_FIELDS,
            encoding="utf-8",
            errors="replace",
        )
    except ValueError:
        raise HTTPException(400, f"Too many fields. Maximum number of fields is {MAX_FIELDS}.") from None
    if any(len(name) + len(value) > MAX_FIELD_CHARS for name, value in fields):
        raise HTTPException(400, f"Field exceeded maximum size of {MAX_FIELD_CHARS // 1024}KB.")
    return FormData(cast(list[tuple[str, str | UploadFile]], fields))  # a list of str pairs is such a list


MAX_FIELDS, MAX_FIELD_CHARS = 64, 32 * 1024


def client_group(address: str) -> str:
    """Whom the login throttle and the arrival limit count as one client: an IPv4 address, or an IPv6 address's /64
    (one subscriber's network, whose addresses a single machine may all hold); anything else, such as a Unix
    socket's name, as it is."""
    try:
        ip = ipaddress.ip_address(address)
    except ValueError:
        return address
    if isinstance(ip, ipaddress.IPv6Address):
        if ip.ipv4_mapped is not None:
            return str(ip.ipv4_mapped)
        return str(ipaddress.IPv6Network((ip, 64), strict=False))
    return str(ip)


class LoginThrottle:
    """Failed admin logins in this process, per client (`client_group`: an IPv4 address or an IPv6 /64) and
    overall. After `free` failures (per client: `free_per_client`; from everyone together: `free_overall`) each
    further attempt must wait a delay that starts at `delay_s` and doubles with every failure, up to `max_delay_s`;
    an attempt during the delay is refused without checking the password. The overall delay holds back every
    client, one never seen included, so a pool of addresses gets no more guesses checked than the overall limit
    allows; only a client that has logged in since the server started passes it (the password is the only way
    in), so the researcher's own address is not locked out by others' guessing. A success clears its client's
    count; counts are forgotten a day after their last failure. The table of clients holds at most `MAX_CLIENTS`:
    when it is full the longest-unseen client makes room once its delay has passed, and until then a new client
    waits as long, so a delayed client is never forgotten. With several worker processes each keeps its own
    counts."""

    FORGET_S = 24 * 3600
    MAX_CLIENTS = 10_000

    def __init__(
        self,
        *,
        free_per_client: int = 5,
        free_overall: int = 100,
        delay_s: float = 1.0,
        max_delay_s: float = 900.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.free_per_client, self.free_overall = free_per_client, free_overall
        self.delay_s, self.max_delay_s = delay_s, max_delay_s
        self.clock = clock
        self.clients: dict[str, tuple[int, float]] = {}  # client -> (failures, time of the last one), oldest first
        self.overall: tuple[int, float] = (0, 0.0)
        self.logged_in: set[str] = set()  # clients the overall delay lets pass
        self.lock = threading.Lock()  # the login endpoint runs in the thread pool

    def _wait(self, count: tuple[int, float], free: int, now: float) -> float:
        failures, last = count
        if failures < free or now - last > self.FORGET_S:
            return 0.0
        delay = min(self.max_delay_s, self.delay_s * 2.0 ** min(failures - free, 40))
        return max(0.0, last + delay - now)

    def _own_wait(self, client: str, now: float) -> float:
        """The client's own delay; a client not in a full table waits for room (for the longest-unseen one's)."""
        own = self.clients.get(client)
        if own is None and len(self.clients) >= self.MAX_CLIENTS:
            own = next(iter(self.clients.values()))
        return 0.0 if own is None else self._wait(own, self.free_per_client, now)

    def wait_s(self, address: str) -> float:
        """Seconds before a client at `address` may try a password again (0: now)."""
        client = client_group(address)
        with self.lock:
            now = self.clock()
            overall = 0.0 if client in self.logged_in else self._wait(self.overall, self.free_overall, now)
            return max(self._own_wait(client, now), overall)

    def failed(self, address: str) -> int:
        """Count a wrong password; returns its client's failures so far."""
        client = client_group(address)
        with self.lock:
            now = self.clock()
            failures, last = self.clients.pop(client, (0, now))
            failures = 1 if now - last > self.FORGET_S else failures + 1
            if len(self.clients) >= self.MAX_CLIENTS and self._own_wait(client, now) == 0:
                self.clients.pop(next(iter(self.clients)))  # the longest unseen, its delay over
            self.clients[client] = (failures, now)
            total, last_any = self.overall
            self.overall = (1 if now - last_any > self.FORGET_S else total + 1, now)
            return failures

    def succeeded(self, address: str) -> None:
        client = client_group(address)
        with self.lock:
            self.clients.pop(client, None)
            self.logged_in.add(client)


class ArrivalLimit:
    """New participants (consent answers) per client (`client_group`: an IPv4 address or an IPv6 /64, so a
    machine cannot pass as many by taking more addresses of its network) in this process: a token bucket of
    `burst` arrivals that refills at `per_minute`. A lab whose participants all start at once behind one address
    passes; a script creating thousands of participants is held to the refill rate. With several worker processes
    each keeps its own buckets."""

    MAX_CLIENTS = 10_000

    def __init__(
        self, *, burst: int = 100, per_minute: float = 60.0, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.burst, self.per_s = burst, per_minute / 60.0
        self.clock = clock
        self.buckets: dict[str, tuple[float, float]] = {}  # client -> (arrivals left, time they were counted)
        self.lock = threading.Lock()  # the consent endpoint runs in the thread pool

    def take(self, address: str) -> float:
        """Count one arrival from `address`: 0 when its client may arrive now, else the seconds until it may."""
        client = client_group(address)
        with self.lock:
            now = self.clock()
            left, then = self.buckets.pop(client, (float(self.burst), now))
            left = min(float(self.burst), left + (now - then) * self.per_s)
            if len(self.buckets) >= self.MAX_CLIENTS:
                self.buckets.pop(next(iter(self.buckets)))  # the longest unseen
            if left >= 1.0:
                self.buckets[client] = (left - 1.0, now)
                return 0.0
            self.buckets[client] = (left, now)
            return (1.0 - left) / self.per_s


ADMIN_SESSIONS = "admin_sessions"


def admin_mark(session: Session, password: str, *, renew: bool = False) -> str:
    """What an admin's session cookie holds once logged in: an HMAC, keyed by the admin password, of the admin
    sessions' version kept in the database. Logging out draws a new version (`renew`), which ends every admin
    session signed before, in every worker; a new password ends them too."""
    row = session.get(ServerSetting, ADMIN_SESSIONS)
    if row is None:
        row = ServerSetting(key=ADMIN_SESSIONS, value=secrets.token_urlsafe(32))
        session.add(row)
    elif renew:
        row.value = secrets.token_urlsafe(32)
    return hmac.new(password.encode(), row.value.encode(), "sha256").hexdigest()


def is_admin(session: Session, password: str, mark: object) -> bool:
    """Whether a session cookie's `mark` is the current one (see `admin_mark`)."""
    row = session.get(ServerSetting, ADMIN_SESSIONS)
    if row is None or not isinstance(mark, str):
        return False
    return hmac.compare_digest(mark, hmac.new(password.encode(), row.value.encode(), "sha256").hexdigest())


def unstorable(text: str) -> str | None:
    """What in `text` a text column cannot hold on every database (PostgreSQL refuses NUL, and no database takes
    an unpaired surrogate), in words for a message; None when it can be stored as it is."""
    if "\x00" in text:
        return "a NUL character (code 0)"
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return "a character that is not valid Unicode (an unpaired surrogate)"
    return None


def stored_secret(session: Session, key: str = "cookie_secret") -> str:
    """A secret generated once and kept in the database, so every worker and every restart share it."""
    row = session.get(ServerSetting, key)
    if row is None:
        row = ServerSetting(key=key, value=secrets.token_urlsafe(48))
        session.add(row)
    return row.value
