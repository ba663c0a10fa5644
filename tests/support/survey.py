"""The survey tests' world: the shipped paper study with names easy to search for in pages, bundles of tiny real
H.264 clips, and a bot that reads and fills in whatever form a page shows."""

from __future__ import annotations

import itertools
import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import imageio_ffmpeg
from fastapi.testclient import TestClient

from app.formats import MANIFEST_FORMAT, Manifest, ManifestClip, manifest_json, sha256_file

REPO = Path(__file__).resolve().parents[2]
PAPER_STUDY = REPO / "studies" / "paper.toml"
# The paper's names, renamed so that a test can assert they never appear in a participant's page.
SECRET_NAMES = {
    "lo": "agentlowsecret",
    "med": "agentmedsecret",
    "hi": "agenthighsecret",
    "adaptive": "schemeadaptivesecret",
    "nfirst": "schemenfirstsecret",
    "paper-bl-tr": "scenarioonesecret",
    "paper-tl-br": "scenariotwosecret",
    "paper-code": "scenarioexamplesecret",
}
AGENT_RANK = ["agentlowsecret", "agentmedsecret", "agenthighsecret"]  # worst to best: the ground truth
ADMIN_PASSWORD = "correct horse battery"
WATCHED = json.dumps([{"type": "loaded", "t": 5}, {"type": "play", "t": 100}, {"type": "ended", "t": 1100}])


def watched_reels(reels: list[int]) -> str:
    """The page's record of the reels `reels` (their places on the screen) played to their end, one after the
    other."""
    events = [{"type": "loaded", "t": 5, "reel": k} for k in reels]
    for n, k in enumerate(reels):
        events += [{"type": "play", "t": 100 + 1100 * n, "reel": k}, {"type": "ended", "t": 1100 * (n + 1), "reel": k}]
    return json.dumps(events)


def make_clip(path: Path, source: str, size: str = "64x64", seconds: float = 1) -> None:
    """A real H.264 clip of ffmpeg's test `source` pattern."""
    subprocess.run(
        [
            imageio_ffmpeg.get_ffmpeg_exe(),
            "-v",
            "error",
            "-y",
            "-f",
            "lavfi",
            "-i",
            f"{source}=size={size}:rate=10:duration={seconds}",
            "-c:v",
            "libx264",
            "-pix_fmt",
            "yuv420p",
            "-movflags",
            "+faststart",
            str(path),
        ],
        check=True,
    )


def write_bundle(root: Path, clip_files: list[Path], *, schemes, scenarios, agents, example=None) -> Path:
    """A manifest with one clip per (scheme, scenario, pair); labels Robot 1..3 follow the agents' order."""
    (root / "clips").mkdir(parents=True, exist_ok=True)
    label = {agent: f"Robot {i + 1}" for i, agent in enumerate(agents)}
    entries = []
    keys = [(s, c, pair) for s in schemes for c in scenarios for pair in itertools.combinations(agents, 2)]
    if example:
        keys.append(example)
    for n, (scheme, scenario, pair) in enumerate(keys):
        source = clip_files[n % len(clip_files)]
        name = f"clips/{n:03d}.mp4"
        shutil.copyfile(source, root / name)
        shown = list(pair) if n % 2 else list(reversed(pair))  # both on-screen orders occur
        entries.append(
            ManifestClip(
                id=f"{scheme}-{scenario}-{pair[0]}-{pair[1]}",
                file=name,
                sha256=sha256_file(root / name),
                scheme=scheme,
                scenario=scenario,
                agents=shown,
                labels=[label[a] for a in shown],
                better=max(pair, key=AGENT_RANK.index) if pair[0] in AGENT_RANK else pair[1],
                summary=f"summaries/{n:03d}.json",
            )
        )
    manifest = Manifest(
        format=MANIFEST_FORMAT,
        clips=entries,
        agents={agent: {"agent": agent, "episodes": 10, "success_rate": 0.5} for agent in agents},
    )
    (root / "manifest.json").write_text(manifest_json(manifest))
    return root


def survey_tables() -> str:
    """The paper study's survey tables without its [build] table: what a study file for a test bundle starts with,
    since `foil bundle` checks the whole file before any search."""
    text_ = PAPER_STUDY.read_text()
    return text_[: text_.index("\n[build]\n")] + "\n"


def study_text(**changes: str) -> str:
    """The shipped paper study with secret names; `changes` replace whole `key = value` lines (key=new value)."""
    text_ = PAPER_STUDY.read_text()
    for old, new in SECRET_NAMES.items():
        text_ = text_.replace(f'"{old}"', f'"{new}"').replace(f"[build.schemes.{old}", f"[build.schemes.{new}")
    for key, value in changes.items():
        text_, n = re.subn(rf"^{key} = .*$", f"{key} = {value}", text_, count=1, flags=re.MULTILINE)
        assert n == 1, key
    return text_


VIDEO_CHECK = """""
[[attention_checks]]
part = 1
after = 1
text = "Did one of the robots touch a person?"
options = ["Yes", "No"]
expected = "Yes"
clip = {{scheme = "{scheme}", scenario = "scenarioexamplesecret", agents = ["agentlowsecret", "agenthighsecret"]}}"""

CLOSING = """""
[closing]
questions = ["age_range", "robot_experience", "confidence"]
feedback = "Anything you want to tell the researchers?"
required = {required}

[questions.age_range]
type = "choice"
text = "Your age"
options = ["18-29", "30-49", "50 or older", "Prefer not to say"]

[questions.robot_experience]
type = "choice"
text = "How much have you worked with robots?"
options = ["Never", "A little", "A lot"]

[questions.confidence]
type = "scale"
text = "How sure were you of your answers?"
points = 5
anchors = ["Not at all", "Completely"]"""

ATTENTION = """
[[attention_checks]]
part = 1
after = 2
text = "This question checks attention. Please choose 'Agree'."
options = ["Disagree", "Agree"]
expected = "Agree"
"""


class FormReader(HTMLParser):
    """Collects a page's form fields: hidden values, radio groups, selects with their options, textareas; and how
    many reels it shows."""

    def __init__(self, page: str):
        super().__init__()
        self.hidden, self.radios, self.selects, self.textareas = {}, {}, {}, []
        self.disabled_answers = False
        self.reels = 0
        self._select = None
        self.feed(page)

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "input" and a.get("type") == "hidden":
            self.hidden[a["name"]] = a.get("value", "")
        elif tag == "input" and a.get("type") == "radio":
            self.radios.setdefault(a["name"], []).append(a["value"])
        elif tag == "select":
            self._select = a["name"]
            self.selects[self._select] = []
        elif tag == "option" and self._select and a.get("value"):
            self.selects[self._select].append(a["value"])
        elif tag == "textarea":
            self.textareas.append(a["name"])
        elif tag == "fieldset" and "data-answers" in a and "disabled" in a:
            self.disabled_answers = True
        elif "data-reel" in a:
            self.reels += 1

    def handle_endtag(self, tag):
        if tag == "select":
            self._select = None


def answer_for(page: str, choice: int = 0) -> dict:
    """A complete, valid answer to whatever screen `page` shows: the `choice`-th option of every radio group,
    a different robot for every ranking place, words in every text box, and a watched clip (every reel)."""
    form = FormReader(page)
    data = dict(form.hidden)
    for name, values in form.radios.items():
        data[name] = values[choice % len(values)]
    for offset, (name, options) in enumerate(sorted(form.selects.items())):
        data[name] = options[(offset + choice) % len(options)]
    for name in form.textareas:
        data[name] = f"Answer to {name}: the robot kept its distance."
    if "video_events" in data:
        data["video_events"] = watched_reels(list(range(form.reels))) if form.reels else WATCHED
        data["time_on_page_ms"] = "4321"
    return data


def start(client: TestClient, query: str = "") -> str:
    """Open the study link and consent; returns the first page after consent."""
    page = client.get(f"/{query}")
    assert page.status_code == 200, page.text
    response = client.post(
        "/consent", data={"csrf_token": FormReader(page.text).hidden["csrf_token"], "choice": "agree"}
    )
    assert response.status_code == 200, response.text
    return response.text


def finish(client: TestClient, page: str, choice: int = 0, limit: int = 60) -> str:
    """Answer every screen until the completion page; returns it."""
    for _ in range(limit):
        form = FormReader(page)
        if "step" not in form.hidden:
            if "number" in form.radios:  # the paper's self-selected condition
                page = client.post(
                    "/condition",
                    data={
                        "csrf_token": form.hidden["csrf_token"],
                        "number": str(choice % len(form.radios["number"]) + 1),
                    },
                ).text
                continue
            return page
        response = client.post("/study", data=answer_for(page, choice))
        assert response.status_code == 200, response.text
        page = response.text
    raise AssertionError("the study did not end")


def walk(client: TestClient, page: str, number: str = "3") -> list[str]:
    """Answer every screen (choosing `number` if asked), returning every page seen."""
    seen = [page]
    while True:
        form = FormReader(page)
        if "number" in form.radios:
            page = client.post("/condition", data={"csrf_token": form.hidden["csrf_token"], "number": number}).text
        elif "step" in form.hidden:
            page = client.post("/study", data=answer_for(page)).text
        else:
            return seen
        seen.append(page)


def stored(client: TestClient, model) -> list:
    """Every row of a table, read straight from the app's database."""
    from sqlalchemy import select

    with client.app.state.context.db.reading() as session:
        return list(session.scalars(select(model).order_by(model.id)))


def log_in(client: TestClient, password: str = ADMIN_PASSWORD):
    page = client.get("/admin/login")
    return client.post(
        "/admin/login", data={"csrf_token": FormReader(page.text).hidden["csrf_token"], "password": password}
    )


CLIP_S = 3.0  # the long clips' playing time: longer than the server's 1-second viewing tolerance


def write_long_bundle(clips: Path, root: Path) -> Path:
    """The paper study's bundle in `root` with clips of CLIP_S seconds (made in `clips`), for the viewing check."""
    clips.mkdir(parents=True, exist_ok=True)
    files = []
    for name, source in (("a", "testsrc"), ("b", "testsrc2")):
        files.append(clips / f"{name}.mp4")
        make_clip(files[-1], source, size="72x88", seconds=CLIP_S)
    names = SECRET_NAMES
    return write_bundle(
        root,
        files,
        schemes=[names["adaptive"], names["nfirst"]],
        scenarios=[names["paper-bl-tr"], names["paper-tl-br"]],
        agents=AGENT_RANK,
        example=(names["nfirst"], names["paper-code"], (names["lo"], names["hi"])),
    )


def planned_bundle(jobs: list, root: Path):
    """A bundle with one manifest entry per clip `foil bundle` plans (`search.bundle.searches.plan_clips`), the first
    agent of each pair the better: what the server's start-up check is given, without searching or rendering."""
    from app.survey.bundle import Bundle
    from search.crowd.render import robot_label

    clips = {
        job.id: ManifestClip(
            id=job.id,
            file=f"clips/{job.id}.mp4",
            sha256=f"{n:064x}",
            scheme=job.scheme.name,
            scenario=job.scenario,
            agents=list(job.pair),
            labels=[robot_label(number) for number in job.numbers],
            better=job.pair[0],
            parts=list(job.parts),
        )
        for n, job in enumerate(jobs)
    }
    return Bundle(root=root, clips=clips, paths={})
