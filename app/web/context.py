"""What every request needs, built once per process by app.web.main.create_app."""

from __future__ import annotations

import secrets
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Annotated, Any

from fastapi import Depends, Request
from fastapi.responses import HTMLResponse
from jinja2 import Environment

from app.store.database import Database
from app.survey.assignment import Condition
from app.survey.bundle import Bundle
from app.survey.study import Study
from app.web.media import KeptClips
from app.web.security import csrf_token
from app.web.settings import ServerSettings

MAX_PAGES = 4096  # about 4 KB each; the paper study with 300 participants showed 544 distinct pages


@dataclass(frozen=True)
class Context:
    settings: ServerSettings
    study: Study
    bundle: Bundle
    conditions: list[Condition]
    db: Database
    templates: Environment
    # Form pages as rendered for any participant, with a placeholder for the session's CSRF token.
    pages: dict[tuple[object, ...], list[str]] = field(default_factory=dict, compare=False)
    csrf_slot: str = field(default_factory=lambda: f"csrf-slot-{secrets.token_hex(16)}", compare=False)
    kept_clips: KeptClips = field(default_factory=KeptClips, compare=False)

    def render(self, request: Request, name: str, status_code: int = 200, **context: Any) -> HTMLResponse:
        html = self.templates.get_template(name).render(
            request=request, study=self.study, words=self.bundle.world.words, csrf_token=csrf_token, **context
        )
        return HTMLResponse(html, status_code=status_code)

    def render_form(
        self, request: Request, key: tuple[object, ...], name: str, context: Callable[[], dict[str, Any]]
    ) -> HTMLResponse:
        """`render` for a page that is the same for everyone who sees it (`key` says which) but for the CSRF token of
        its form: it is rendered once and then only the session's token is filled in. `context()` gives the
        template's variables, and is called only to render."""
        pieces = self.pages.get(key)
        if pieces is None:
            html = self.templates.get_template(name).render(
                request=None,
                study=self.study,
                words=self.bundle.world.words,
                csrf_token=lambda _request: self.csrf_slot,
                **context(),
            )
            if len(self.pages) >= MAX_PAGES:
                self.pages.clear()
            pieces = self.pages[key] = html.split(self.csrf_slot)
        return HTMLResponse(csrf_token(request).join(pieces) if len(pieces) > 1 else pieces[0])

    def message(self, request: Request, title: str, text: str, status_code: int = 200, **context: Any) -> HTMLResponse:
        return self.render(request, "message.html", status_code=status_code, title=title, text=text, **context)


async def get_context(request: Request) -> Context:
    """Async on purpose: FastAPI runs plain functions in its thread pool, a hop that costs more than this does."""
    context: Context = request.app.state.context
    return context


ContextDep = Annotated[Context, Depends(get_context)]
