"""The FastAPI application: everything is loaded and checked once, at start-up, so a bad study file, a bundle
that does not match it or an unmigrated database stops the server with a message instead of failing participants."""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, PlainTextResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from sqlalchemy.exc import IntegrityError
from starlette.exceptions import HTTPException
from starlette.middleware.sessions import SessionMiddleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import ClientDisconnect

from app.analysis.source import remember_study
from app.page_templates import STATIC_DIR, page_templates
from app.store.database import Database, check_migrated
from app.survey.assignment import conditions
from app.survey.bundle import check_study_against_bundle, load_bundle
from app.survey.study import load_study
from app.web import admin_pages, analysis_pages, media, participant_pages
from app.web.context import Context
from app.web.security import (
    ArrivalLimit,
    BodyLimitMiddleware,
    LoginThrottle,
    SecurityHeadersMiddleware,
    stored_secret,
)
from app.web.settings import ServerSettings

log = logging.getLogger("foil.server")


def _cookie_secret(settings: ServerSettings, db: Database) -> str:
    if settings.secret_key is not None:
        return settings.secret_key.get_secret_value()
    try:
        with db.writing() as session:
            return stored_secret(session)
    except IntegrityError:  # another worker created it at the same moment
        with db.reading() as session:
            return stored_secret(session)


def create_app(settings: ServerSettings) -> FastAPI:
    """Build the app for an already migrated database (`foil serve` migrates first)."""
    study = load_study(settings.study_path())
    bundle = load_bundle(settings.bundle_dir)
    check_study_against_bundle(study, bundle)
    db = Database(settings.database_url, synchronous=settings.sqlite_synchronous)
    check_migrated(db.engine)
    remember_study(db, settings.study_path().read_bytes(), study, bundle.root)  # for foil report (and --prereg)

    context = Context(
        settings=settings, study=study, bundle=bundle, conditions=conditions(study), db=db, templates=page_templates()
    )

    app = FastAPI(title="Foil survey", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.context = context
    app.state.login_throttle = LoginThrottle(
        free_per_client=settings.login_free_attempts,
        free_overall=settings.login_free_attempts_overall,
        delay_s=settings.login_delay_s,
        max_delay_s=settings.login_max_delay_s,
    )
    app.state.arrivals = ArrivalLimit(burst=settings.arrivals_burst, per_minute=settings.arrivals_per_minute)
    app.include_router(participant_pages.router)
    app.include_router(media.router)
    app.mount("/static", StaticFiles(directory=str(STATIC_DIR)), name="static")
    if settings.admin_password is None:
        log.warning(
            "FOIL_ADMIN_PASSWORD is not set: the admin pages are off (set it, 8 characters or more, and "
            "restart the server)"
        )
        app.include_router(admin_pages.disabled_router)
    else:
        app.include_router(admin_pages.router)
        app.include_router(analysis_pages.router)

    @app.exception_handler(HTTPException)
    async def _http_error(request: Request, error: HTTPException) -> HTMLResponse:
        titles = {
            400: "Bad request",
            403: "Not allowed",
            404: "Page not found",
            405: "Not allowed",
            409: "Not available yet",
            413: "Too large",
            429: "Please wait a moment",
            503: "Busy",
        }
        text = error.detail if isinstance(error.detail, str) else "The request could not be handled."
        page = context.message(request, titles.get(error.status_code, "Error"), text, status_code=error.status_code)
        page.headers.update(error.headers or {})
        return page

    @app.exception_handler(admin_pages.LoginRequired)
    async def _login_first(request: Request, error: admin_pages.LoginRequired) -> RedirectResponse:
        return RedirectResponse("/admin/login", status_code=303)

    @app.exception_handler(RequestValidationError)
    async def _bad_request(request: Request, error: RequestValidationError) -> HTMLResponse:
        fields = "; ".join(f"{e['loc'][-1]} ({e['msg'].lower()})" for e in error.errors())
        return context.message(
            request, "Bad request", f"The request is missing or has invalid fields: {fields}.", status_code=400
        )

    @app.exception_handler(ClientDisconnect)
    async def _gone(request: Request, error: ClientDisconnect) -> Response:
        log.info(
            "%s %s from %s: the client left before its request had arrived",
            request.method,
            request.url.path,
            request.client.host if request.client else "?",
        )
        return Response(status_code=400)  # nobody reads it

    security_headers = SecurityHeadersMiddleware(app, frame_ancestors=settings.frame_ancestors)

    @app.exception_handler(Exception)
    async def _server_error(request: Request, error: Exception) -> PlainTextResponse:
        # Starlette's outermost layer sends this (and logs the error): the middlewares below never see it.
        return PlainTextResponse(
            "Something went wrong on the server. What you had already submitted is saved; "
            "please go back and try again in a moment.",
            status_code=500,
            headers={name.decode(): value.decode() for name, value in security_headers.headers},
        )

    app.router.redirect_slashes = False  # its redirect is built from the Host header
    # Innermost first: every reply, the body limit's 413 and the host check's 400 included, gets the headers.
    # Clips and static files never touch the session, so their replies carry no cookie and no Vary: Cookie.
    app.add_middleware(
        SessionMiddleware,
        secret_key=_cookie_secret(settings, db),
        session_cookie="foil_session",
        max_age=settings.session_max_age_s,
        same_site=settings.cookie_samesite,
        https_only=settings.cookie_secure,
    )
    app.add_middleware(BodyLimitMiddleware, limit=settings.max_body_bytes)
    if settings.allowed_hosts != ["*"]:
        app.add_middleware(TrustedHostMiddleware, allowed_hosts=settings.allowed_hosts, www_redirect=False)
    app.add_middleware(SecurityHeadersMiddleware, frame_ancestors=settings.frame_ancestors)
    return app


def app_from_env() -> FastAPI:
    """For `uvicorn --factory app.web.main:app_from_env --workers N` with FOIL_* variables (run migrations first)."""
    return create_app(ServerSettings())  # type: ignore[call-arg]  # pydantic-settings reads the fields from FOIL_* variables
