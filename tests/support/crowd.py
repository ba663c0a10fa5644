"""A crowd of `foil simulate` bots (app.analysis.bots.Bot) taking a study at once against a real server, each in its own
thread, for the crash test and the load benchmark.

Each bot talks through a `LoopbackClient`: a lean keep-alive HTTP/1.1 client on a plain socket (httpx costs about
four times as much CPU per request as http.client, and http.client's header parsing, through the email package,
costs more than the rest of a request; on a 2-core machine the load generator cannot spare it). It follows
redirects, keeps the session cookie, times every exchange, pauses before each form it sends (a person reading the
page), and remembers every answer the server acknowledged. A bot whose server goes away waits for it to come back
and reopens its link, which resumes its record, as a person would.
"""

from __future__ import annotations

import http.client
import random
import socket
import threading
import time
from dataclasses import dataclass, field
from types import SimpleNamespace
from urllib.parse import urlencode, urlsplit

from app.analysis.bots import Bot, ClipIndex, Observer

# Errors of a connection that the server dropped or refused (it crashed, or is restarting).
CONNECTION_ERRORS = (OSError, http.client.HTTPException)


PAGE_TYPES = {
    ("GET", "/"): "landing",
    ("POST", "/consent"): "consent",
    ("GET", "/study"): "study page",
    ("POST", "/study"): "answer",
    ("POST", "/condition"): "condition",
}


def page_type(method: str, path: str) -> str:
    """The kind of request, for latency per page type."""
    if path.startswith("/clips/"):
        return "clip"
    return PAGE_TYPES.get((method, path), f"{method} {path}")


@dataclass
class Exchange:
    kind: str
    status: int
    seconds: float
    at: float  # time.monotonic() when the reply was complete


class Reply:
    """The parts of a response that app.analysis.bots.Bot reads."""

    def __init__(self, method: str, path: str, status: int, text: str):
        self.status_code, self.text = status, text
        self.request = SimpleNamespace(method=method, url=SimpleNamespace(path=path))


class LoopbackClient:
    """get/post like httpx.Client for one participant: one keep-alive connection, its cookie, redirects.

    HTTP/1.1 as the survey server speaks it: every request goes out in one write (head and form together, as
    browsers send a small form), every reply has a Content-Length."""

    def __init__(self, base_url: str, *, pause_s: float = 0.0, log: list[Exchange] | None = None):
        parts = urlsplit(base_url)
        self.host, self.port = parts.hostname, parts.port
        self.pause_s = pause_s
        self.log = log if log is not None else []
        self.cookies: dict[str, str] = {}
        self.acknowledged: list[dict] = []  # every /study form the server answered with success
        self.connection: socket.socket | None = None

    def get(self, path: str, params: dict | None = None, headers: dict | None = None) -> Reply:
        return self._follow("GET", path + ("?" + urlencode(params) if params else ""), None, headers or {})

    def post(self, path: str, data: dict) -> Reply:
        if self.pause_s:
            time.sleep(self.pause_s)  # reading the page and answering it
        return self._follow(
            "POST",
            path,
            urlencode(data),
            {"Content-Type": "application/x-www-form-urlencoded"},
            sent={name: str(value) for name, value in data.items()},
        )

    def close(self) -> None:
        if self.connection is not None:
            self.connection.close()
            self.connection = None

    def _follow(self, method: str, target: str, body: str | None, headers: dict, sent: dict | None = None) -> Reply:
        for _ in range(5):
            status, location, text = self._exchange(method, target, body, headers)
            if method == "POST" and target == "/study" and status == 303:
                self.acknowledged.append(sent)
            if status not in (301, 302, 303, 307, 308):
                return Reply(method, target.split("?")[0], status, text)
            method, target, body, headers = "GET", location, None, {}
        raise http.client.HTTPException(f"too many redirects from {target}")

    def _exchange(self, method: str, target: str, body: str | None, headers: dict) -> tuple[int, str, str]:
        head = [f"{method} {target} HTTP/1.1", f"Host: {self.host}:{self.port}"]
        head += [f"{name}: {value}" for name, value in headers.items()]
        if self.cookies:
            head.append("Cookie: " + "; ".join(f"{name}={value}" for name, value in self.cookies.items()))
        content = body.encode() if body is not None else b""
        if body is not None:
            head.append(f"Content-Length: {len(content)}")
        request = "\r\n".join(head).encode("latin-1") + b"\r\n\r\n" + content
        for attempt in (1, 2):
            reused = self.connection is not None
            if self.connection is None:
                self.connection = socket.create_connection((self.host, self.port), timeout=120)
            started = time.monotonic()
            try:
                self.connection.sendall(request)
                status, fields, data = self._reply(method)
            except CONNECTION_ERRORS:
                self.close()
                # A kept-alive connection the server had closed: send again on a new one, as browsers do.
                if reused and attempt == 1:
                    continue
                raise
            done = time.monotonic()
            self.log.append(Exchange(page_type(method, target.split("?")[0]), status, done - started, done))
            location = ""
            for name, value in fields:
                if name == "set-cookie":
                    cookie, _, _ = value.partition(";")
                    key, _, text = cookie.partition("=")
                    self.cookies[key.strip()] = text.strip()
                elif name == "location":
                    location = value
                elif name == "connection" and value.lower() == "close":
                    self.close()
            return status, location, data.decode("utf-8", "replace")
        raise AssertionError("unreachable")

    def _reply(self, method: str) -> tuple[int, list[tuple[str, str]], bytes]:
        """Status, header fields (names in lower case) and body of the next reply on the connection."""
        received = bytearray()
        while (end := received.find(b"\r\n\r\n")) < 0:
            received += self._receive(65536)
        status_line, *lines = received[:end].decode("latin-1").split("\r\n")
        status = int(status_line.split(" ", 2)[1])
        fields = []
        for line in lines:
            name, _, value = line.partition(":")
            fields.append((name.strip().lower(), value.strip()))
        names = dict(fields)
        if "chunked" in names.get("transfer-encoding", ""):
            raise http.client.HTTPException("a chunked reply: the survey server sends a Content-Length")
        length = 0 if method == "HEAD" or status in (204, 304) else int(names.get("content-length", 0))
        body = received[end + 4 :]
        while len(body) < length:
            body += self._receive(length - len(body))
        return status, fields, bytes(body[:length])

    def _receive(self, size: int) -> bytes:
        data = self.connection.recv(size)
        if not data:
            raise http.client.RemoteDisconnected("the server closed the connection")
        return data


@dataclass
class Participant:
    """One bot of the crowd and what happened to it."""

    bot: Bot
    client: LoopbackClient
    interruptions: int = 0
    error: str = ""

    @property
    def external_id(self) -> str:
        return self.bot.run.external_id


@dataclass
class Crowd:
    """`participants` bots against `url`, started `ramp_s` apart in all, each pausing `pause_s` before every form.

    `run` returns when every bot has finished or failed; a bot that loses its server waits for it (up to
    `outage_s`) and reopens its link."""

    url: str
    bundle_dir: str
    participants: int
    pause_s: float = 0.0
    ramp_s: float = 0.0
    seed: int = 0
    outage_s: float = 120.0
    clips: ClipIndex | None = None  # the bundle's clips as the bots see them; read from bundle_dir if not given
    log: list[Exchange] = field(default_factory=list)
    people: list[Participant] = field(default_factory=list)

    def __post_init__(self):
        clips, observer = self.clips or ClipIndex(self.bundle_dir), Observer()
        for k in range(self.participants):
            client = LoopbackClient(self.url, pause_s=self.pause_s, log=self.log)
            bot = Bot(
                client,
                clips,
                observer,
                random.Random(f"{self.seed}:{k}"),
                number=k,
                external_id=f"load-{self.seed}-{k}",
            )
            self.people.append(Participant(bot, client))

    def _server_back(self) -> bool:
        """Wait until the server accepts connections again (at most `outage_s`)."""
        deadline = time.monotonic() + self.outage_s
        parts = urlsplit(self.url)
        while time.monotonic() < deadline:
            try:
                socket.create_connection((parts.hostname, parts.port), timeout=5).close()
                return True
            except OSError:
                time.sleep(0.2)
        return False

    def _take(self, person: Participant, delay: float) -> None:
        time.sleep(delay)
        try:
            while True:
                try:
                    person.bot.take_study()
                    return
                except CONNECTION_ERRORS as error:
                    person.client.close()
                    person.interruptions += 1
                    if not self._server_back():
                        person.error = f"the server was gone for {self.outage_s} s: {error!r}"
                        return
        except Exception as error:  # noqa: BLE001 - every failure is reported by the caller
            person.error = f"{type(error).__name__}: {error}"
        finally:
            person.client.close()

    def run(self) -> float:
        """Run the crowd; returns the wall time it took."""
        started = time.monotonic()
        threads = [
            threading.Thread(target=self._take, args=(person, self.ramp_s * k / max(1, self.participants)), daemon=True)
            for k, person in enumerate(self.people)
        ]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        return time.monotonic() - started

    @property
    def completed(self) -> int:
        return sum(person.bot.run.completed for person in self.people)

    @property
    def errors(self) -> list[str]:
        return [f"{person.external_id}: {person.error}" for person in self.people if person.error]


@dataclass
class Audit:
    """What the database holds after a crowd's run, against what the bots were told was saved."""

    participants: int
    responses: int  # answered screens in the database
    acknowledged: int  # answers the server acknowledged with success
    missing: list[str]  # acknowledged answers not in the database, or stored with other values
    duplicated: list[str]  # external ids with more than one record
    conditions: dict[int, int]  # participants per condition
    balance_problems: list[str]

    @property
    def ok(self) -> bool:
        return not (self.missing or self.duplicated or self.balance_problems)


def _same(stored: dict, sent: dict) -> bool:
    """Whether the answers stored for a screen are the ones the form sent (rankings come as NAME-1, NAME-2...)."""
    for name, value in stored.items():
        if isinstance(value, list):
            if value != [sent.get(f"{name}-{place}") for place in range(1, len(value) + 1)]:
                return False
        elif str(value) != sent.get(name):
            return False
    return True


def audit(database_url: str, crowd: Crowd, *, seed: int, n_conditions: int) -> Audit:
    """Every acknowledged answer stored as sent; one record per bot; arrival slots 0..n-1 with no gap, each
    with its permuted block's condition, so that the conditions' counts differ by at most one."""
    from collections import Counter

    from sqlalchemy import select

    from app.store.database import Database
    from app.store.models import Participant as Record
    from app.store.models import Response
    from app.survey.assignment import condition_for_slot

    db = Database(database_url)
    try:
        with db.reading() as session:
            records = list(session.scalars(select(Record)))
            stored = {
                (p.external_id, r.step): r.answers
                for p, r in session.execute(
                    select(Record, Response).join(Response, Response.participant_id == Record.id)
                )
            }
    finally:
        db.dispose()
    missing, acknowledged = [], 0
    for person in crowd.people:
        for sent in person.client.acknowledged:
            acknowledged += 1
            key = (person.external_id, int(sent["step"]))
            if key not in stored:
                missing.append(f"{key}: acknowledged, not in the database")
            elif not _same(stored[key], sent):
                missing.append(f"{key}: stored {stored[key]}, sent {sent}")
    ids = Counter(p.external_id for p in records)
    slots = sorted(p.slot for p in records if p.slot is not None)
    balance = []
    if slots != list(range(len(slots))):
        balance.append(f"arrival slots are not 0..{len(slots) - 1} without gaps: {slots}")
    wrong = [
        p.external_id
        for p in records
        if p.slot is not None and p.condition != condition_for_slot(seed=seed, n_conditions=n_conditions, slot=p.slot)
    ]
    if wrong:
        balance.append(f"participants whose condition is not their slot's: {wrong}")
    counts = Counter(p.condition for p in records)
    if max(counts.values(), default=0) - min((counts[c] for c in range(n_conditions)), default=0) > 1:
        balance.append(f"conditions' counts differ by more than one: {dict(counts)}")
    return Audit(
        participants=len(records),
        responses=len(stored),
        acknowledged=acknowledged,
        missing=missing,
        duplicated=[i for i, n in ids.items() if n > 1],
        conditions=dict(sorted(counts.items())),
        balance_problems=balance,
    )
