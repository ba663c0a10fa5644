"""A participant takes the whole paper study in headless Chromium: consent, the number, instructions, clips played
to their end before the answers unlock, the ranking by keyboard alone, the completion code; on a desktop and a
360 x 740 phone screen; with reloads, the back button, double clicks and a closed and reopened link on the way.
Every page is photographed and checked with axe-core. The admin then finds the participant and the answers in
the export."""

from __future__ import annotations

import csv
import io
import json
from collections import Counter

import httpx
import pytest
from sqlalchemy import select

from app.store.database import Database
from app.store.models import Participant, Response
from tests.support.browser import ARTIFACTS, DESKTOP, PHONE, SERIOUS
from tests.support.survey import ADMIN_PASSWORD, finish, start

pytestmark = pytest.mark.browser

FREE_TEXT = "Robot 1 kept its distance — 距离 <script>alert('x')</script> & \"quotes\""


def link(worker: str) -> str:
    return f"/?workerId={worker}&assignmentId=A-{worker}&hitId=HIT1"


class Walker:
    """Drives one participant's page: photographs and axe-checks every new page, answers whatever it shows."""

    def __init__(self, page, base_url: str, name: str, *, axe: bool = True):
        self.page, self.base_url, self.axe = page, base_url, axe
        self.folder = ARTIFACTS / name
        self.folder.mkdir(parents=True, exist_ok=True)
        self.shots = 0
        self.violations: dict[str, list] = {}
        self.answers: dict[int, dict] = {}  # step -> what was answered

    def open(self, path: str) -> None:
        self.page.goto(self.base_url + path)
        self.look()

    def step(self) -> int | None:
        field = self.page.locator("input[name=step]")
        return int(field.get_attribute("value")) if field.count() else None

    def kind(self) -> str:
        page = self.page
        if page.locator("form[action='/consent']").count():
            return "consent"
        if page.locator("form[action='/condition']").count():
            return "condition"
        if page.locator("#completion-code").count():
            return "complete"
        if page.locator("select[name^=ranking]").count():
            return "ranking"
        if self.step() == 0:
            return "instructions"
        if page.locator("[data-answers]").count():
            return "clip"
        if self.step() is not None:
            return "instructions"
        return "other"

    def look(self) -> None:
        """Screenshot and accessibility check of the page now shown."""
        self.page.wait_for_load_state("load")
        self.shots += 1
        label = f"{self.shots:02d}-{self.kind()}" + (f"-step{self.step()}" if self.step() is not None else "")
        self.page.screenshot(path=str(self.folder / f"{label}.png"), full_page=True)
        if not self.axe:
            return
        found = self.page.evaluate("async () => (await axe.run(document, {resultTypes: ['violations']})).violations")
        serious = [
            {
                "id": v["id"],
                "impact": v["impact"],
                "help": v["help"],
                "nodes": [node["html"][:200] for node in v["nodes"]],
            }
            for v in found
            if v["impact"] in SERIOUS
        ]
        if serious:
            self.violations[label] = serious

    def submit(self, selector: str = "button[type=submit]", *, double: bool = False) -> None:
        with self.page.expect_navigation():
            if double:
                self.page.dblclick(selector)
            else:
                self.page.click(selector)
        self.look()

    def watch(self) -> None:
        """Play the clip to its end: the answers stay disabled until then."""
        next_button = self.page.locator("fieldset[data-answers] button[type=submit]")
        assert next_button.is_disabled(), "the answers were open before the clip was watched"
        text_box = "fieldset[data-answers] textarea"
        locked = None
        if self.page.locator(text_box).count():  # a locked text box looks locked, not like one to type in
            locked = self.page.eval_on_selector(text_box, "e => getComputedStyle(e).backgroundColor")
            assert locked != "rgb(255, 255, 255)", locked
        self.page.wait_for_function("() => document.querySelector('video').readyState >= 2")
        self.page.click("[data-play]")
        self.page.wait_for_function("() => document.querySelector('video').ended", timeout=20_000)
        assert next_button.is_enabled()
        if locked is not None:
            assert self.page.eval_on_selector(text_box, "e => getComputedStyle(e).backgroundColor") != locked
        played = self.page.evaluate(
            "(() => { const v = document.querySelector('video'); return [v.currentTime, v.duration]; })()"
        )
        assert played[1] > 0.5 and played[0] >= played[1] - 0.05, played

    def answer_clip(self, choice: int) -> dict:
        """Pick robot `choice`, write the free text, choose a scale point; returns what was given."""
        given = {}
        better = self.page.locator("input[name=better]")
        if better.count():
            value = better.nth(choice % better.count()).get_attribute("value")
            self.page.check(f"input[name=better][value='{value}']")
            self.page.fill("textarea[name=justification]", FREE_TEXT)
            self.page.check("input[name=difficulty][value='3']")
            given = {"better": value, "justification": FREE_TEXT, "difficulty": 3}
        return given

    def rank_by_keyboard(self) -> dict:
        """Fill the whole ranking page with the keyboard alone: Tab to each field, type or choose, Enter."""
        options = self.page.locator("select[name=ranking-1] option[value]:not([value=''])").all_inner_texts()
        order = list(reversed(options))
        given = {"ranking": order, "explanation": FREE_TEXT}
        self.page.keyboard.press("Tab")
        for _ in range(80):
            focused = self.page.evaluate(
                "(() => { const e = document.activeElement;"
                " return [e.tagName, e.name || '', e.type || '', e.checked || false]; })()"
            )
            tag, name, kind, checked = focused
            if tag == "SELECT" and name.startswith("ranking-"):
                self.page.keyboard.type(order[int(name.split("-")[1]) - 1])
            elif tag == "TEXTAREA":
                self.page.keyboard.type(FREE_TEXT)
            elif kind == "radio":
                self.page.keyboard.press("ArrowRight")  # move to the second point and select it
                given[name] = int(self.page.evaluate("document.activeElement.value"))
            elif tag == "BUTTON" and kind == "submit":
                with self.page.expect_navigation():
                    self.page.keyboard.press("Enter")
                self.look()
                return given
            self.page.keyboard.press("Tab")
        raise AssertionError("the ranking page's submit button was never reached with Tab")

    def answer_current(self, choice: int = 0, *, double: bool = False) -> str:
        """Answer whatever the page shows and go on; returns the kind of page answered."""
        kind = self.kind()
        step = self.step()
        if kind == "consent":
            self.submit("button[value=agree]", double=double)
        elif kind == "condition":
            self.page.check(f"input[name=number][value='{choice % 4 + 1}']")
            self.submit(double=double)
        elif kind == "instructions":
            if self.page.locator("video").count():  # the example is watched before the study starts
                self.watch()
            self.submit(double=double)
        elif kind == "clip":
            self.watch()
            self.answers[step] = self.answer_clip(choice)
            self.submit(double=double)
        elif kind == "ranking":
            self.answers[step] = self.rank_by_keyboard()
        else:
            raise AssertionError(f"nothing to answer on {kind} page:\n{self.page.content()[:2000]}")
        return kind

    def finish(self, limit: int = 40) -> str:
        for _ in range(limit):
            if self.kind() == "complete":
                return self.page.inner_text("#completion-code")
            self.answer_current()
        raise AssertionError("the study did not end")


def stored(server, worker: str) -> tuple[list[Participant], list[Response]]:
    db = Database(server.database_url)
    try:
        with db.reading() as session:
            people = list(session.scalars(select(Participant).where(Participant.external_id == worker)))
            responses = list(
                session.scalars(
                    select(Response).where(Response.participant_id.in_([p.id for p in people])).order_by(Response.step)
                )
            )
    finally:
        db.dispose()
    return people, responses


def check_saved(server, worker: str, walker: Walker) -> None:
    """One record, completed, one response per screen, and the answers as given."""
    people, responses = stored(server, worker)
    assert len(people) == 1 and people[0].status == "completed"
    assert [r.step for r in responses] == list(range(len(people[0].plan)))
    for r in responses:
        for name, value in walker.answers.get(r.step, {}).items():
            assert r.answers[name] == value, (r.step, name)


@pytest.mark.parametrize("viewport", [DESKTOP, PHONE], ids=["desktop", "phone"])
def test_whole_paper_study_in_chromium(server, new_context, viewport):
    worker = f"W{viewport['width']}"
    name = "desktop" if viewport is DESKTOP else "phone"
    page = new_context(viewport).new_page()
    walker = Walker(page, server.url, name)
    walker.open(link(worker))
    assert walker.kind() == "consent"
    code = walker.finish()
    assert code == "FOIL-PAPER-7Q2K"
    kinds = Counter(name.split("-")[1] for name in (p.stem for p in walker.folder.glob("*.png")))
    assert kinds["clip"] == 12 and kinds["ranking"] == 2 and kinds["complete"] == 1
    assert walker.violations == {}, json.dumps(walker.violations, indent=1)
    if viewport is PHONE:  # nothing wider than the screen
        assert page.evaluate("document.documentElement.scrollWidth") <= PHONE["width"]
    check_saved(server, worker, walker)


def test_reload_back_double_click_and_reopening_keep_one_record(server, new_context):
    worker = "WRESUME"
    context = new_context()
    walker = Walker(context.new_page(), server.url, "resume", axe=False)  # the pages are checked above
    walker.open(link(worker))
    walker.answer_current()  # consent
    walker.answer_current()  # number
    walker.answer_current()  # instructions
    walker.answer_current(double=True)  # first clip, submitted with a double click
    assert walker.step() == 2
    walker.page.reload()
    walker.look()
    assert walker.step() == 2  # a reload shows the same screen
    walker.answer_current()
    walker.page.go_back()
    walker.look()
    assert walker.step() == 3  # the back button shows the current screen, not the answered one
    walker.answer_current()
    assert walker.step() == 4

    walker.page.close()  # closing the tab and opening the link again, same browser
    walker.page = context.new_page()
    walker.open(link(worker))
    assert walker.step() == 4
    walker.answer_current(double=True)

    other = Walker(new_context().new_page(), server.url, "resume-other-browser", axe=False)  # same link
    other.open(link(worker))
    assert other.step() == 5
    other.answers = walker.answers
    assert other.finish() == "FOIL-PAPER-7Q2K"
    check_saved(server, worker, other)


def test_admin_sees_the_participant_and_exports_the_answers(server, new_context):
    worker = "WADMIN"
    with httpx.Client(base_url=server.url, follow_redirects=True) as client:  # a quick participant over HTTP
        assert "FOIL-PAPER-7Q2K" in finish(client, start(client, link(worker)[1:]), choice=1)
    people, responses = stored(server, worker)
    given = [(r.step, name, value) for r in responses for name, value in r.answers.items()]
    assert len(given) == 6 * 3 + 2 * 5  # part one: 3 questions on 6 clips; part two: 5 questions twice

    admin = Walker(new_context().new_page(), server.url, "admin")
    admin.page.goto(server.url + "/admin")
    assert admin.page.url.endswith("/admin/login")
    admin.look()
    admin.page.fill("#password", "not the password")
    admin.submit()
    assert "Wrong password" in admin.page.content()
    admin.page.fill("#password", ADMIN_PASSWORD)
    admin.submit()
    row = admin.page.locator("tr", has_text=worker)
    assert row.count() == 1 and "completed" in row.inner_text()
    with admin.page.expect_navigation():
        row.locator("a").click()
    admin.look()
    assert people[0].code in admin.page.content()
    with admin.page.expect_download() as download:
        admin.page.click("a[href='/admin/export.csv']")
    rows = list(csv.DictReader(io.StringIO(download.value.path().read_text(encoding="utf-8-sig"))))
    mine = [r for r in rows if worker in r.values() or people[0].code in r.values()]
    cells = Counter(value for r in mine for value in r.values())
    assert cells["Answer to justification: the robot kept its distance."] == 6
    assert cells["Answer to explanation: the robot kept its distance."] == 2
    exported = {(int(r["step"]), r["question"]): r for r in mine if r["question"]}
    assert len(exported) == len(given)
    for step, name, value in given:
        assert exported[(step, name)]["answer"] == (">".join(value) if name == "ranking" else str(value))
    assert admin.violations == {}, json.dumps(admin.violations, indent=1)


def test_other_participant_pages_are_accessible(server, new_context):
    """The pages off the main path: HIT preview, an answer refused with its messages, leaving, declining."""
    walker = Walker(new_context(PHONE).new_page(), server.url, "other-pages")
    walker.open("/?workerId=WPREVIEW&assignmentId=ASSIGNMENT_ID_NOT_AVAILABLE&hitId=HIT1")
    assert walker.kind() == "other" and "preview" in walker.page.url.lower() + walker.page.content().lower()
    walker.open(link("WOTHER"))
    for _ in range(3):
        walker.answer_current()  # consent, number, instructions
    walker.watch()
    with walker.page.expect_navigation():  # sent without answers, past the browser's own checks
        walker.page.evaluate("document.querySelector('form[data-step-form]').submit()")
    walker.look()
    assert walker.page.locator(".error-summary").count() == 1 and walker.step() == 1
    walker.open("/leave")
    walker.submit()
    assert "You have left the study" in walker.page.content()

    decliner = Walker(new_context().new_page(), server.url, "other-pages-decline")
    decliner.open(link("WDECLINE"))
    decliner.submit("button[value=decline]")
    assert decliner.kind() == "other"
    assert walker.violations == {} and decliner.violations == {}, json.dumps(
        walker.violations | decliner.violations, indent=1
    )


def test_the_accessibility_check_finds_violations(server, new_context):
    """The check above can fail: a button without a name on a real page is reported."""
    walker = Walker(new_context().new_page(), server.url, "axe-self-check")
    walker.open(link("WAXE"))
    assert walker.violations == {}
    walker.page.evaluate("document.querySelector('main').append(document.createElement('button'))")
    walker.look()
    assert [v["id"] for found in walker.violations.values() for v in found] == ["button-name"]
