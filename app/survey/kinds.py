"""Who a participant is: a real participant, a pilot (the researcher's preview link from the admin overview) or a
bot (`foil simulate`). The kind is recorded on the participant; the export and the report leave pilots and bots
out by default.

The pilot link carries the study's pilot token, generated once and kept in the database. With it a pilot or bot
is not held to the clip's playing time on the server (so bots can finish a study fast). A link that only says
`bot=1`, without the token, is recorded as a bot and held to the same viewing rules as anyone: a participant who
adds it only takes themselves out of the analysis.
"""

from __future__ import annotations

import hmac
import secrets
from collections.abc import Mapping

from sqlalchemy.exc import IntegrityError

from app.store.database import Database
from app.store.models import ServerSetting

KINDS = ("real", "pilot", "bot")
TOKEN_KEY = "pilot-token:"
_tokens: dict[tuple[str, str], str] = {}


def pilot_token(db: Database, study_id: str) -> str:
    """The study's pilot token, created on first use (any process: the first writer wins)."""
    cached = _tokens.get((db.url, study_id))
    if cached:
        return cached
    key = TOKEN_KEY + study_id
    with db.reading() as session:
        row = session.get(ServerSetting, key)
        token = row.value if row is not None else None
    if token is None:
        try:
            with db.writing() as session:
                row = session.get(ServerSetting, key)
                if row is None:
                    session.add(ServerSetting(key=key, value=secrets.token_urlsafe(18)))
        except IntegrityError:
            pass
        with db.reading() as session:
            token = session.get_one(ServerSetting, key).value
    _tokens[(db.url, study_id)] = token
    return token


def kind_from_link(params: Mapping[str, str], token: str) -> tuple[str, bool]:
    """(kind, fast) from the study link's parameters: `pilot=TOKEN` makes a pilot (with `bot=1`, a bot), both
    exempt from the server's viewing-time rule (`fast`); `bot=1` alone a bot held to the rules."""
    sent = params.get("pilot") or ""
    valid = bool(sent) and hmac.compare_digest(sent.encode(), token.encode())
    bot = params.get("bot") == "1"
    if valid:
        return ("bot" if bot else "pilot"), True
    return ("bot" if bot else "real"), False
