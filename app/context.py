"""What every request needs, built once per process by app.main.create_app."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Request
from fastapi.responses import HTMLResponse
from jinja2 import Environment

from app.assignment import Condition
from app.bundle import Bundle
from app.database import Database
from app.settings import Settings
from app.study import Study


@dataclass(frozen=True)
class Context:
    settings: Settings
    study: Study
    bundle: Bundle
    conditions: list[Condition]
    db: Database
    templates: Environment

    def render(self, request: Request, name: str, status_code: int = 200, **context) -> HTMLResponse:
        html = self.templates.get_template(name).render(request=request, study=self.study, **context)
        return HTMLResponse(html, status_code=status_code)

    def message(self, request: Request, title: str, text: str, status_code: int = 200, **context):
        return self.render(request, "message.html", status_code=status_code, title=title, text=text, **context)


async def get_context(request: Request) -> Context:
    """Async on purpose: FastAPI runs plain functions in its thread pool, a hop that costs more than this does."""
    return request.app.state.context


ContextDep = Annotated[Context, Depends(get_context)]
