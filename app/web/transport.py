"""Limits uvicorn's HTTP protocol does not set by itself, for a survey open to the internet: the size and number of
a request's header fields (431 beyond them), and the time a request may take to arrive, headers and body (a
client that sends too slowly, or opens a connection and sends nothing, is cut off instead of holding a
connection for as long as it likes). Keep-alive between requests is uvicorn's own `timeout_keep_alive`.

`foil serve` runs uvicorn with `survey_protocol(limits)`; with uvicorn's command line (several workers) pass
`--http app.web.transport:SurveyHttpProtocol`, which reads the same FOIL_* variables (see `TransportLimits`)."""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from app.web.security import security_headers
from app.web.settings import TransportLimits

log = logging.getLogger("foil.server")
# What every reply written here carries: the app's security headers.
HEADERS = b"content-type: text/plain; charset=utf-8\r\nconnection: close\r\n" + b"".join(
    name + b": " + value + b"\r\n" for name, value in security_headers()
)
REASONS = {400: b"Bad Request", 408: b"Request Timeout", 431: b"Request Header Fields Too Large"}


class _HeadTooLarge(Exception):
    pass


class LimitedHttpToolsProtocol(HttpToolsProtocol):
    """uvicorn's httptools protocol with the limits of `limits` (a class attribute, see `survey_protocol`)."""

    limits: TransportLimits = TransportLimits()

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._deadline: asyncio.TimerHandle | None = None
        self._head_bytes = self._head_fields = 0
        self._in_head = True
        self._refused: str | None = None

    # The deadline: armed when a connection opens and when a request begins, disarmed once it has fully arrived.
    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]  # as uvicorn narrows it
        super().connection_made(transport)
        self._arm()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        super().connection_lost(exc)

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._head_bytes = self._head_fields = 0
        self._in_head = True
        if self._deadline is None:
            self._arm()

    def on_headers_complete(self) -> None:
        self._in_head = False
        super().on_headers_complete()

    def on_message_complete(self) -> None:
        self._disarm()
        super().on_message_complete()

    def _arm(self) -> None:
        self._disarm()
        self._deadline = self.loop.call_later(self.limits.request_timeout_s, self._too_slow)

    def _disarm(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _too_slow(self) -> None:
        self._deadline = None
        if self.transport.is_closing():
            return
        client = "{}:{}".format(*self.client) if self.client else "a client"
        if self._in_head:
            log.info("%s sent no complete request within %s s: closed with 408", client, self.limits.request_timeout_s)
            self._reply(408, f"The request did not arrive within {self.limits.request_timeout_s} seconds.")
        else:  # the app is waiting for the rest of the body: it sees the client leave
            log.info(
                "%s did not send the body of %s %s within %s s: closed",
                client,
                self.scope.get("method"),
                self.scope.get("path"),
                self.limits.request_timeout_s,
            )
            self.transport.close()

    # The size of the request line and header fields.
    def on_url(self, url: bytes) -> None:
        self._grow(len(url), 0)
        super().on_url(url)

    def on_header(self, name: bytes, value: bytes) -> None:
        self._grow(len(name) + len(value) + 4, 1)
        super().on_header(name, value)

    def _grow(self, size: int, fields: int) -> None:
        self._head_bytes += size
        self._head_fields += fields
        if self._head_bytes > self.limits.max_header_bytes:
            self._refused = f"The request's header fields exceed {self.limits.max_header_bytes} bytes."
        elif self._head_fields > self.limits.max_headers:
            self._refused = f"The request has more than {self.limits.max_headers} header fields."
        else:
            return
        raise _HeadTooLarge  # the parser stops and reports an error: see send_400_response

    def send_400_response(self, msg: str) -> None:
        """uvicorn's reply to a request its parser refuses, with the security headers; 431 for our limits."""
        if self._refused is None:
            self._reply(400, msg)
            return
        log.info("%s: refused with 431: %s", "{}:{}".format(*self.client) if self.client else "a client", self._refused)
        self._reply(431, self._refused)

    def _reply(self, status: int, text: str) -> None:
        self._disarm()
        body = text.encode()
        self.transport.write(
            b"HTTP/1.1 %d %s\r\n" % (status, REASONS[status])
            + HEADERS
            + b"content-length: %d\r\n\r\n" % len(body)
            + body
        )
        self.transport.close()


def survey_protocol(limits: TransportLimits) -> type[LimitedHttpToolsProtocol]:
    """The protocol class for uvicorn's `http` setting, with these limits."""
    return type("SurveyHttpProtocol", (LimitedHttpToolsProtocol,), {"limits": limits})


# For `uvicorn --http app.web.transport:SurveyHttpProtocol`: the limits from the FOIL_* variables.
SurveyHttpProtocol = LimitedHttpToolsProtocol
