"""In Chromium, against `foil serve` with 3-second clips whose summaries say how each robot ends: on a desktop the
whole clip and its controls are in the first view at 1366x768, 1280x720 and 1440x900 (the phone keeps one column);
a ranking round's clips are large, show how they ended and say it in words; a watch-only screen says what its
clip unlocks; the back button leads to the current screen with a short notice; the admin's answers table uses the
page's width. Screenshots go to test-artifacts/browser/layout/."""

from __future__ import annotations

import json

import httpx
import pytest

from app.store.database import Database
from app.survey.kinds import pilot_token
from tests.support.analysis import summary_for
from tests.support.browser import ARTIFACTS, long_clip_server
from tests.support.survey import ADMIN_PASSWORD, finish, start

pytestmark = pytest.mark.browser
DESKTOPS = [{"width": 1366, "height": 768}, {"width": 1280, "height": 720}, {"width": 1440, "height": 900}]
PHONE = {"width": 360, "height": 740}
SHOTS = ARTIFACTS / "layout"
NEXT = "fieldset[data-answers] button[type=submit]"


FIRST_ROBOT = 13  # the bundle's robots are Robots 13 to 15: the numbers of the demo's representative round


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    def with_summaries(bundle):
        (bundle / "summaries").mkdir()
        manifest = json.loads((bundle / "manifest.json").read_text())
        for clip in manifest["clips"]:
            (bundle / clip["summary"]).write_text(json.dumps(summary_for(clip["agents"], misleading=False)))
            clip["labels"] = [f"Robot {int(label.split()[-1]) + FIRST_ROBOT - 1}" for label in clip["labels"]]
        (bundle / "manifest.json").write_text(json.dumps(manifest))

    with long_clip_server(tmp_path_factory.mktemp("browser-layout"), with_summaries) as live:
        yield live


def shoot(page, name: str) -> None:
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / f"{name}.png"))  # the first view only: what is above the fold


def pilot(server) -> str:
    db = Database(server.database_url)
    try:
        return f"?pilot={pilot_token(db, 'paper')}"
    finally:
        db.dispose()


def to_instructions(page, server) -> None:
    page.goto(server.url + "/" + pilot(server))
    with page.expect_navigation():
        page.click("button[value=agree]")
    page.wait_for_function("() => document.querySelector('video').readyState >= 2")


def to_first_clip(page, server) -> None:
    to_instructions(page, server)
    with page.expect_navigation():  # a pilot is not held to the example's playing time
        page.evaluate(
            "() => { document.querySelector('fieldset[data-answers]').disabled = false; "
            "document.querySelector('form[data-step-form]').requestSubmit(); }"
        )
    assert page.locator("input[name=step]").get_attribute("value") == "1"
    page.wait_for_function("() => document.querySelector('video').readyState >= 2")


def answer_unwatched(page) -> None:
    """A pilot's answer to the screen shown, without playing its clip (the server does not hold pilots to it)."""
    page.evaluate("""() => {
        document.querySelector('fieldset[data-answers]').disabled = false;
        document.querySelector('[data-events]').value = JSON.stringify([{type: 'play', t: 0}, {type: 'ended', t: 1}]);
        for (const name of ['better', 'difficulty', 'attention']) {
            const first = document.querySelector(`input[name=${name}]`); if (first) first.checked = true; }
        const text = document.querySelector('textarea'); if (text) text.value = 'a reason';
    }""")
    with page.expect_navigation():
        page.click(NEXT)


def box(page, selector: str) -> dict:
    return page.evaluate(f"""() => {{ const r = document.querySelector({json.dumps(selector)}).getBoundingClientRect();
        return {{top: r.top, bottom: r.bottom, left: r.left, width: r.width, height: r.height}}; }}""")


@pytest.mark.parametrize("viewport", DESKTOPS, ids=lambda v: f"{v['width']}x{v['height']}")
def test_the_whole_clip_and_its_controls_are_in_the_first_view_on_a_desktop(server, new_context, viewport):
    page = new_context(viewport).new_page()
    to_first_clip(page, server)
    shoot(page, f"clip-{viewport['width']}x{viewport['height']}")
    assert page.evaluate("window.scrollY") == 0
    video, play, status = box(page, ".screen-clip video"), box(page, "[data-play]"), box(page, "[data-status]")
    assert video["top"] >= 0 and video["bottom"] <= viewport["height"]
    assert play["bottom"] <= viewport["height"] and status["bottom"] <= viewport["height"]
    assert video["height"] >= 0.55 * viewport["height"]  # large, not shrunk to fit below the text
    assert page.evaluate("document.documentElement.scrollWidth") <= viewport["width"]
    question = box(page, "input[name=better]")
    assert question["left"] > video["left"] + video["width"]  # the questions beside the clip


@pytest.mark.parametrize("viewport", DESKTOPS, ids=lambda v: f"{v['width']}x{v['height']}")
def test_the_example_clip_and_the_unlocked_questions_fit_the_first_view_on_a_desktop(server, new_context, viewport):
    """The instructions' example clip stands beside their text, and once a clip has played, its questions, its
    robot key and the Next button fit beside it: nothing cut off at the window's bottom edge."""
    page = new_context(viewport).new_page()
    to_instructions(page, server)
    shoot(page, f"instructions-{viewport['width']}x{viewport['height']}")
    example, play = box(page, "video[data-example]"), box(page, "[data-play]")
    assert 0 <= example["top"] and example["bottom"] <= viewport["height"] and play["bottom"] <= viewport["height"]
    assert example["height"] >= 0.55 * viewport["height"]
    with page.expect_navigation():
        page.evaluate(
            "() => { document.querySelector('fieldset[data-answers]').disabled = false; "
            "document.querySelector('form[data-step-form]').requestSubmit(); }"
        )
    page.wait_for_function("() => document.querySelector('video').readyState >= 2")
    page.click("[data-play]")
    page.wait_for_function("() => document.querySelector('video').ended", timeout=20_000)
    assert page.locator(NEXT).is_enabled()
    shoot(page, f"unlocked-{viewport['width']}x{viewport['height']}")
    assert page.evaluate("window.scrollY") == 0
    for selector in (NEXT, ".screen-clip .robot-key", "[data-status]"):
        assert box(page, selector)["bottom"] <= viewport["height"], selector


def test_a_phone_shows_the_play_button_first_a_full_width_example_and_a_short_ranking_page(server, new_context):
    page = new_context(PHONE).new_page()
    to_instructions(page, server)
    assert box(page, "video[data-example]")["width"] >= PHONE["width"] - 40
    with page.expect_navigation():
        page.evaluate(
            "() => { document.querySelector('fieldset[data-answers]').disabled = false; "
            "document.querySelector('form[data-step-form]').requestSubmit(); }"
        )
    page.wait_for_function("() => document.querySelector('video').readyState >= 2")
    shoot(page, "first-clip-phone")
    assert box(page, "[data-play]")["bottom"] <= PHONE["height"]  # the clip and its Play button in the first view
    for _ in range(20):
        if page.locator("select[name^=ranking]").count():
            break
        answer_unwatched(page)
    page.screenshot(path=str(SHOTS / "ranking-phone-full.png"), full_page=True)
    figures = [page.locator(".round-clips figure").nth(k).bounding_box() for k in range(3)]
    assert len({round(figure["y"]) for figure in figures}) == 1  # one row, scrolled sideways: one clip high
    assert figures[0]["width"] >= 0.8 * (PHONE["width"] - 32)  # each clip still nearly the column's width
    assert PHONE["width"] - figures[1]["x"] >= 40  # the next clip shows a good part of itself
    assert page.locator("[data-swipe-hint]").is_visible()  # and a line says the row scrolls sideways
    assert page.evaluate("document.documentElement.scrollHeight") <= 3.5 * PHONE["height"]
    assert page.evaluate("document.documentElement.scrollWidth") <= PHONE["width"]


def lab(rgb: tuple[float, float, float]) -> list[float]:
    """CIE L*a*b* (D65) of an sRGB colour."""
    linear = [v / 255 / 12.92 if v / 255 <= 0.04045 else ((v / 255 + 0.055) / 1.055) ** 2.4 for v in rgb]
    xyz = [
        (0.4124 * linear[0] + 0.3576 * linear[1] + 0.1805 * linear[2]) / 0.9505,
        0.2126 * linear[0] + 0.7152 * linear[1] + 0.0722 * linear[2],
        (0.0193 * linear[0] + 0.1192 * linear[1] + 0.9505 * linear[2]) / 1.089,
    ]
    f = [v ** (1 / 3) if v > 0.008856 else 7.787 * v + 16 / 116 for v in xyz]
    return [116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])]


def each_screen_with_robots(page, server, look) -> int:
    """`look(page, labels)` on every screen with a robot key, from the first clip to the first ranking page; how
    many screens it looked at."""
    to_first_clip(page, server)
    seen = 0
    for _ in range(20):
        labels = [text.strip() for text in page.locator(".robot-key li").all_inner_texts()]
        if labels:
            look(page, labels)
            seen += 1
            if page.locator("select[name^=ranking]").count():
                break
        answer_unwatched(page)
    assert seen >= 7  # six pairwise screens, a ranking round's clips and its ranking page
    return seen


def test_the_answers_list_the_robots_in_the_order_of_the_clips_legend(server, new_context):
    """A clip's legend lists its robots by number (search/clips/render.py); so do the key and every answer."""

    def look(page, labels):
        assert labels == sorted(labels, key=lambda label: int(label.split()[-1]))
        options = page.evaluate("[...document.querySelectorAll('input[name=better]')].map(e => e.value)")
        ranked = page.evaluate(
            "[...document.querySelectorAll('select[name^=ranking]')]"
            ".map(s => [...s.options].slice(1).map(o => o.value))"
        )
        assert all(order == labels for order in [options, *ranked] if order)

    each_screen_with_robots(new_context(DESKTOPS[0]).new_page(), server, look)


def test_the_robots_of_a_clip_and_of_a_round_have_clearly_different_colours(server, new_context):
    """The key's colours are the clips' own (search/clips/render.py) and far apart (CIE76 distance over 50): not
    Robot 13 in sky blue beside Robot 15 in blue."""
    from search.clips.render import agent_style

    def look(page, labels):
        colours = page.evaluate(
            "[...document.querySelectorAll('.robot-key .marker')].map(m => getComputedStyle(m).backgroundColor)"
        )
        rgb = [tuple(float(v) for v in colour[colour.index("(") + 1 : -1].split(",")) for colour in colours]
        assert sorted(rgb) == sorted(agent_style(int(label.split()[-1]))[0] for label in labels)
        for i, a in enumerate(rgb):
            for b in rgb[i + 1 :]:
                assert sum((x - y) ** 2 for x, y in zip(lab(a), lab(b), strict=True)) ** 0.5 > 50, labels

    each_screen_with_robots(new_context(DESKTOPS[0]).new_page(), server, look)


def test_the_phone_keeps_one_column(server, new_context):
    page = new_context(PHONE).new_page()
    to_first_clip(page, server)
    shoot(page, "clip-phone")
    title, video, question = box(page, "h1"), box(page, ".screen-clip video"), box(page, "input[name=better]")
    assert title["bottom"] <= video["top"] < question["top"]  # text, clip, questions, one under the other
    assert video["width"] >= PHONE["width"] - 40
    assert page.evaluate("document.documentElement.scrollWidth") <= PHONE["width"]


def test_the_back_button_shows_the_current_screen_with_a_short_notice(server, new_context):
    page = new_context(DESKTOPS[0]).new_page()
    to_first_clip(page, server)
    notice = page.locator("[data-back-notice]")
    assert not notice.is_visible()
    answer_unwatched(page)
    assert page.locator("input[name=step]").get_attribute("value") == "2" and not notice.is_visible()
    page.go_back()
    page.wait_for_load_state("load")
    assert page.locator("input[name=step]").get_attribute("value") == "2"
    assert notice.is_visible() and "cannot be changed" in notice.inner_text()
    assert len(notice.inner_text()) < 120
    shoot(page, "back-notice")
    page.reload()
    assert not page.locator("[data-back-notice]").is_visible()  # said once


def test_watch_only_screens_ranking_clips_and_places(server, new_context):
    page = new_context(DESKTOPS[0]).new_page()
    to_first_clip(page, server)
    for _ in range(20):  # through part one to the first clip that is only watched
        if (
            page.locator("video").count()
            and not page.locator("input[name=better]").count()
            and not page.locator("input[name=attention]").count()
        ):
            break
        answer_unwatched(page)
    status = page.locator("[data-status]")
    page.wait_for_function("() => document.querySelector('video').readyState >= 2")
    assert "The Next button unlocks when the clip ends." in status.inner_text()
    assert "answer" not in status.inner_text()
    shoot(page, "watch-only")
    page.click("[data-play]")
    page.wait_for_function("() => document.querySelector('video').ended", timeout=20_000)
    assert "Press Next to go on" in status.inner_text() and page.locator(NEXT).is_enabled()
    with page.expect_navigation():
        page.click(NEXT)
    for _ in range(5):
        if page.locator("select[name^=ranking]").count():
            break
        answer_unwatched(page)
    page.wait_for_function(
        "() => [...document.querySelectorAll('.round-clips video')].every("
        "v => v.readyState >= 2 && v.currentTime > v.duration - 0.2)"
    )
    shoot(page, "ranking")
    videos = page.locator(".round-clips video")
    assert videos.count() == 3
    box_colour = page.evaluate("getComputedStyle(document.querySelector('.round-clips video')).backgroundColor")
    assert min(int(v) for v in box_colour[box_colour.index("(") + 1 : -1].split(",")[:3]) > 200  # no dark edge
    for k in range(3):  # large enough to read the labels drawn in the clip: well over the 220 px of before
        assert videos.nth(k).bounding_box()["width"] >= 360
    ended = page.evaluate(
        "() => [...document.querySelectorAll('.round-clips video')].map(v => [v.paused, v.duration - v.currentTime])"
    )
    assert all(paused and left < 0.2 for paused, left in ended)  # each shows its last frame: how it ended
    outcomes = [page.locator(".round-clips figure").nth(k).locator(".outcomes li").all_inner_texts() for k in range(3)]
    assert all(len(texts) == 2 for texts in outcomes)
    assert all(text.startswith("Robot ") and text.endswith(".") for texts in outcomes for text in texts)
    assert any("bumped into a person" in text for texts in outcomes for text in texts)  # the worst robot
    places = page.locator(".rank-place label").all_inner_texts()
    assert places == ["1. best", "2. middle", "3. worst"]
    page.locator(".round-clips [data-play]").first.click()
    page.wait_for_timeout(600)
    assert 0 < page.evaluate("document.querySelector('.round-clips video').currentTime") < 2.0  # from the start
    assert {e["type"] for e in json.loads(page.locator("[data-events]").input_value())} <= {"loaded", "play"}


def test_the_admin_answers_table_uses_the_page_width_and_the_site_has_an_icon(server, new_context):
    with httpx.Client(base_url=server.url, follow_redirects=True) as client:
        finish(client, start(client, pilot(server)))
    page = new_context(DESKTOPS[0]).new_page()
    page.goto(server.url + "/admin/login")
    page.fill("#password", ADMIN_PASSWORD)
    with page.expect_navigation():
        page.click("button[type=submit]")
    with page.expect_navigation():
        page.locator("table.participants a").first.click()
    shoot(page, "admin-participant")
    page.screenshot(path=str(SHOTS / "admin-participant-full.png"), full_page=True)
    broken = page.evaluate("""() => {
        const broken = [];
        for (const cell of document.querySelectorAll('table.answers td')) {
            const walker = document.createTreeWalker(cell, NodeFilter.SHOW_TEXT);
            for (let node = walker.nextNode(); node; node = walker.nextNode()) {
                for (const match of node.data.matchAll(/\\S+/g)) {
                    const range = document.createRange();
                    range.setStart(node, match.index); range.setEnd(node, match.index + match[0].length);
                    const lines = new Set([...range.getClientRects()].map(r => Math.round(r.top)));
                    if (lines.size > 1) broken.push(match[0]);
                }
            }
        }
        return broken;
    }""")
    assert broken == []
    wrap = page.evaluate(
        "() => { const w = document.querySelector('table.answers').parentElement;"
        " return [w.scrollWidth, w.clientWidth, w.getBoundingClientRect().width]; }"
    )
    assert wrap[0] <= wrap[1] and wrap[2] > 1000  # the page's width, no sideways scrolling
    icon = page.evaluate("document.querySelector('link[rel=icon]').href")
    reply = httpx.get(icon)
    assert reply.status_code == 200 and reply.headers["content-type"].startswith("image/svg+xml")
