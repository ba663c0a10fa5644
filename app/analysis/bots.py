"""`foil simulate`: bot participants that take the real study over HTTP, like oTree's bots, judging each clip the
way a viewer would.

A bot reads each page's form, fetches the clip the page points to (as a browser would), and answers from what the
clip visibly shows. It knows a clip by its address (the sha256 in /clips/SHA.mp4; a pair of reels by both reels'),
finds it in the bundle and reads the clip's summary.json (a reel's: its segments'): which agent collided, which
reached the goal and when, which timed out, how close each came to people. The observer model turns that into a
score per agent (a reel's agent: averaged over its segments), by the rule of the bundle's world
(`app.visible.World`), plus Gaussian perception noise; the ground truth (`better` in the manifest, the agents'
evaluations) is never read. A three-way question (which is better, or no difference) reads as "no difference"
when the two perceived scores differ by less than the clip's tie margin (`VisibleClip.margin`: the observer's
`tie_margin`, or where the world's visible score judges the clip, any difference that shows on screen).
"""

from __future__ import annotations

import html
import json
import random
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from app.formats import Manifest, Summary, load_summary
from app.survey.clip_length import clip_shape
from app.survey.study import NO_DIFFERENCE
from app.visible import Observer, Visible, VisibleClip, VisibleReels, contrast


class ClipIndex:
    """The bundle's clips by address (a clip's sha256; a pair of reels' sha256s joined by "+", in the order shown),
    each as what it visibly shows, read from its summary.json (a reel's, from its segments'), judged by the rule and
    described in the words of the bundle's world."""

    def __init__(self, bundle_dir: str | Path):
        root = Path(bundle_dir)
        try:
            manifest = Manifest.model_validate_json((root / "manifest.json").read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ValueError(f"no manifest.json in bundle {root}") from None
        world = manifest.shown_world()
        self.clips: dict[str, Visible] = {}
        self.lengths_ms: dict[str, int] = {}  # what the server holds each clip's answers for (reels: their sum)
        for entry in manifest.clips:
            if entry.reels:
                if not all(reel.summaries for reel in entry.reels):
                    raise ValueError(f"clip {entry.id!r}: a reel lists no segments; the bots judge reels by them")
                key = "+".join(reel.sha256.lower() for reel in entry.reels)
                segments = [[_summary(root, entry.id, name) for name in reel.summaries] for reel in entry.reels]
                self.clips[key] = VisibleReels.of_summaries(segments, entry.labels, world)
                files = [root / reel.file for reel in entry.reels]
            else:
                key = entry.sha256.lower()
                summary = _summary(root, entry.id, entry.summary)
                self.clips[key] = VisibleClip.of_summary(summary, entry.agents, entry.labels, world)
                files = [root / entry.file]
            if all(file.is_file() for file in files):
                self.lengths_ms[key] = sum(clip_shape(file).ms for file in files)

    def at(self, urls: list[str]) -> tuple[str, Visible]:
        """The clip a page shows in the videos at ``urls``: its address and what it shows."""
        shas = re.findall(r"/clips/([0-9a-f]{64})\.mp4", " ".join(urls))
        key = "+".join(shas)
        if len(shas) != len(urls) or key not in self.clips:
            raise ValueError(f"the page shows clip {' and '.join(urls)}, which is not in the bundle given to the bots")
        return key, self.clips[key]


def _summary(root: Path, clip: str, name: str) -> Summary:
    path = root / name
    if not name or not path.is_file():
        raise ValueError(f"clip {clip!r}: no summary file {path}; the bots judge clips from it")
    return load_summary(path)


# The tags of a page that a form is made of (name, attributes), and one attribute (name, value in double quotes,
# single quotes or none). The server's pages are well-formed and have no inline scripts, so a bot need not parse
# the rest: html.parser, which reads every tag and text, costs several times as much, and under load the bots share
# the machine with the server.
FORM_TAG = re.compile(
    r"<(/?)(form|fieldset|legend|label|input|select|option|textarea|video)\b"
    r"((?:[^>\"']|\"[^\"]*\"|'[^']*')*)>",
    re.IGNORECASE,
)
HTML_ATTRIBUTE = re.compile(r"""([^\s=/>"']+)(?:\s*=\s*(?:"([^"]*)"|'([^']*)'|([^\s>"']+)))?""")
ANY_TAG = re.compile(r"<[^>]*>")
COMPLETION_CODE = re.compile(r"""\sid=["']?completion-code\b[^>]*>""")  # the rest of the tag with this id


def _attributes(text: str) -> dict[str, str]:
    pairs = {}
    for match in HTML_ATTRIBUTE.finditer(text):
        name, double, single, bare = match.groups()
        value = double if double is not None else single if single is not None else bare or ""
        pairs[name.lower()] = html.unescape(value) if "&" in value else value
    return pairs


def _text(fragment: str) -> str:
    """The text of a piece of a page, without its tags, spaces collapsed."""
    return " ".join(html.unescape(ANY_TAG.sub("", fragment)).split())


class PageForm:
    """The answerable parts of a page: hidden fields, radio groups with their legend and option labels, ranking
    selects, text boxes, the clip's address and the completion code."""

    def __init__(self, page: str):
        self.action = ""
        self.hidden: dict[str, str] = {}
        self.radios: dict[str, list[tuple[str, str]]] = {}  # name -> [(value, label text)]
        self.legends: dict[str, str] = {}  # radio group or select prefix -> its question
        self.selects: dict[str, list[str]] = {}
        self.textareas: list[str] = []
        self.videos: list[str] = []  # the screen's clip, or its reels in the order shown
        self.answerable = False  # a study screen (not the instructions' example)
        legend = ""  # the legend of the innermost fieldset begun so far
        legend_at = label_at = -1  # where the legend or label being read begins
        radio: tuple[str, str] | None = None  # the radio button of the label being read
        select: str | None = None
        for match in FORM_TAG.finditer(page):
            closing, tag, attributes = match.groups()
            tag = tag.lower()
            if closing:
                if tag == "legend" and legend_at >= 0:
                    legend, legend_at = _text(page[legend_at : match.start()]), -1
                elif tag == "label" and label_at >= 0:
                    if radio:
                        self.radios[radio[0]].append((radio[1], _text(page[label_at : match.start()])))
                    label_at = -1
                elif tag == "select":
                    select = None
                continue
            if tag == "fieldset":
                legend = ""
                self.answerable |= "data-answers" in _attributes(attributes)
                continue
            if tag == "legend":
                legend_at = match.end()
                continue
            if tag == "label":
                label_at, radio = match.end(), None
                continue
            a = _attributes(attributes)
            if tag == "form":
                self.action = a.get("action", "")
            elif tag == "input" and a.get("type") == "hidden":
                self.hidden[a["name"]] = a.get("value", "")
            elif tag == "input" and a.get("type") == "radio":
                self.radios.setdefault(a["name"], [])
                self.legends[a["name"]] = legend
                radio = (a["name"], a["value"])
            elif tag == "select":
                select = a["name"]
                self.selects[select] = []
                self.legends[select.rsplit("-", 1)[0]] = legend
            elif tag == "option" and select and a.get("value"):
                self.selects[select].append(a["value"])
            elif tag == "textarea":
                self.textareas.append(a["name"])
            elif tag == "video" and "data-example" not in a and "data-round" not in a:
                self.videos.append(a.get("src", ""))  # the screen's; not the instructions' example or a replay
        code = COMPLETION_CODE.search(page)
        self.code = (
            "".join(
                html.unescape(piece).strip() for piece in ANY_TAG.split(page[code.end() : page.find("</", code.end())])
            )
            if code
            else ""
        )


class BotError(RuntimeError):
    """The server answered a bot with something a participant could not go on from."""


class Reply(Protocol):
    """What a bot reads of a response: httpx.Response's status, text and request (method, url.path)."""

    @property
    def status_code(self) -> int: ...

    @property
    def text(self) -> str: ...

    @property
    def request(self) -> Any: ...


class Client(Protocol):
    """What a bot needs of its HTTP client: httpx.Client's get and post (tests and benchmarks bring their own)."""

    def get(self, url: str, *, params: dict[str, str] = ..., headers: dict[str, str] = ...) -> Reply: ...

    def post(self, url: str, *, data: dict[str, str]) -> Reply: ...


@dataclass
class BotRun:
    """What one bot did: its identity, whether it finished, and every answer with the clip it was about."""

    external_id: str
    completed: bool = False
    completion_code: str = ""
    answers: list[dict[str, Any]] = field(default_factory=list)  # {step, clip (address or None), question, value}


class Bot:
    """One participant: a fresh cookie jar, its own seeded randomness, and memory of the clips of the current
    ranking block."""

    def __init__(
        self,
        client: Client,
        clips: ClipIndex,
        observer: Observer,
        rng: random.Random,
        *,
        number: int,
        external_id: str,
        attentive: bool = True,
        link: dict[str, str] | None = None,
        fast: bool = False,
    ) -> None:
        self.client, self.clips, self.observer, self.rng = client, clips, observer, rng
        self.number, self.attentive = number, attentive
        self.link = {"bot": "1", **(link or {})}  # marks the participant as a bot; `pilot=TOKEN` for the fast mode
        self.fast = fast  # with the pilot token the server does not hold answers for the clip's playing time
        self.run = BotRun(external_id=external_id)
        self.block: list[tuple[str, dict[str, float]]] = []  # (clip, perceived scores) since the last ranking
        self.refused: dict[str, set[str]] = {}  # question -> answers the server refused (a wrong comprehension answer)

    def _ok(self, response: Reply) -> str:
        if response.status_code != 200:
            text = re.sub(r"<[^>]+>", " ", response.text)
            raise BotError(
                f"{response.request.method} {response.request.url.path}: HTTP {response.status_code}: "
                f"{' '.join(text.split())[:300]}"
            )
        return response.text

    def take_study(self, max_pages: int = 500) -> BotRun:
        """Open the study link and answer every page to the end. Calling it again (after a lost connection, say)
        reopens the link, which resumes where the server says this participant is."""
        ids = {
            "PROLIFIC_PID": self.run.external_id,
            "STUDY_ID": "simulated",
            "SESSION_ID": self.run.external_id,
            "workerId": self.run.external_id,
            "hitId": "simulated",
            "assignmentId": self.run.external_id,
        }
        page = self._ok(self.client.get("/", params=ids | self.link))
        for _ in range(max_pages):
            form = PageForm(page)
            if form.action == "/consent":
                page = self._ok(
                    self.client.post("/consent", data={"csrf_token": form.hidden["csrf_token"], "choice": "agree"})
                )
            elif form.action == "/condition":
                n = len(form.radios["number"])
                page = self._ok(
                    self.client.post(
                        "/condition", data={"csrf_token": form.hidden["csrf_token"], "number": str(self.number % n + 1)}
                    )
                )
            elif "step" in form.hidden:
                shown = time.monotonic()
                data = self.answer(form)
                if form.videos and not self.fast:  # watch the clip: the server's clock checks it
                    wait = self.clips.lengths_ms.get(self.clips.at(form.videos)[0], 0) / 1000 + 0.2
                    time.sleep(max(0.0, shown + wait - time.monotonic()))
                response = self.client.post("/study", data=data)
                if response.status_code == 422 and self._choose_again(form, data):
                    page = response.text  # the same screen, saying what to change: answer it again
                    continue
                page = self._ok(response)
                if form.selects:  # the ranking is saved; forget its clips only now, so a lost reply can be retried
                    self.block = []
            else:
                self.run.completed = bool(form.code) or "Thank you" in page
                self.run.completion_code = form.code
                return self.run
        raise BotError(f"bot {self.run.external_id}: the study did not end after {max_pages} pages")

    def _watch(self, form: PageForm) -> tuple[str, Visible, dict[str, float], int]:
        """Fetch the start of the clip (of each reel) like a browser (Range request) and look at it."""
        sha, clip = self.clips.at(form.videos)
        for video in form.videos:
            response = self.client.get(video, headers={"Range": "bytes=0-1023"})
            if response.status_code not in (200, 206):
                raise BotError(f"clip {video}: HTTP {response.status_code}")
        return sha, clip, self.observer.perceive(clip, self.rng), int(clip.end_s * 1000)

    def answer(self, form: PageForm) -> dict[str, str]:
        data = {"csrf_token": form.hidden["csrf_token"], "step": form.hidden["step"]}
        step = int(form.hidden["step"])
        seen: dict[str, float]
        sha, clip, seen, clip_ms = None, None, {}, 0
        if form.videos:
            sha, clip, seen, clip_ms = self._watch(form)
            data["video_events"] = json.dumps(_played(clip))
            if form.answerable and not (form.radios or form.textareas):
                self.block.append((sha, seen))  # a clip of a ranking block: remember it for the ranking
        ranked = self._ranking() if form.selects else []
        margin = clip.margin(self.observer) if clip is not None else 0.0
        for name, options in form.radios.items():
            data[name] = self._radio(name, options, form.legends.get(name, ""), seen, ranked, margin)
        for prefix in {name.rsplit("-", 1)[0] for name in form.selects}:
            for place, label in enumerate(ranked, start=1):
                data[f"{prefix}-{place}"] = label
            self.run.answers.append(
                {
                    "step": step,
                    "clip": None,
                    "clips": [sha for sha, _ in self.block],
                    "question": prefix,
                    "value": ranked,
                }
            )
        for name in form.textareas:
            data[name] = self._explain(clip, seen, ranked)
        for name in form.radios:
            self.run.answers.append({"step": step, "clip": sha, "question": name, "value": data[name]})
        data["time_on_page_ms"] = str(clip_ms + 800 + self.rng.randint(3000, 15000))
        return data

    def _choose_again(self, form: PageForm, data: dict[str, str]) -> bool:
        """After a refused answer, as a person who reads the error: rule out the choices just refused, and say
        whether every refused choice question still has another option to try."""
        for name in form.radios:
            self.refused.setdefault(name, set()).add(data[name])
        return bool(form.radios) and all(
            len(self.refused[name]) < len(options) for name, options in form.radios.items()
        )

    def _ranking(self) -> list[str]:
        """Best first: most clips won, then the higher mean perceived score."""
        wins: dict[str, int] = {}
        scores: dict[str, list[float]] = {}
        for _, seen in self.block:
            best = max(seen, key=seen.__getitem__)
            for label, score in seen.items():
                wins[label] = wins.get(label, 0) + (label == best)
                scores.setdefault(label, []).append(score)
        return sorted(wins, key=lambda label: (-wins[label], -sum(scores[label]) / len(scores[label])))

    def _pair_contrast(self, a: str, b: str) -> float:
        together = [seen for _, seen in self.block if a in seen and b in seen]
        if together:
            return contrast(together[-1][a], together[-1][b])
        mean = {label: [s[label] for _, s in self.block if label in s] for label in (a, b)}
        return contrast(*(sum(values) / len(values) if values else 0.0 for values in mean.values()))

    def _radio(
        self,
        name: str,
        options: list[tuple[str, str]],
        legend: str,
        seen: dict[str, float],
        ranked: list[str],
        margin: float,
    ) -> str:
        """`margin`: how far apart two perceived scores must be to look different (the clip's, by the world's rule)."""
        values = [value for value, _ in options]
        agents = [value for value in values if value != NO_DIFFERENCE]
        if seen and len(agents) == 2 and NO_DIFFERENCE in values and set(agents) <= set(seen):  # better, or none
            first, second = (seen[agent] for agent in agents)
            return NO_DIFFERENCE if abs(first - second) < margin else max(agents, key=seen.__getitem__)
        if seen and set(values) <= set(seen):  # which agent is better
            return max(values, key=seen.__getitem__)
        if all(value.isdigit() for value in values):
            return str(self._scale_point(options, legend, seen, ranked))
        quoted = re.findall(r"['\"‘“]([^'\"’”]+)['\"’”]", legend)
        asked = [value for value in values if value in quoted]
        if self.attentive and asked:  # an instructed-response item: do what it says
            return asked[0]
        return self.rng.choice([value for value in values if value not in self.refused.get(name, ())] or values)

    def _scale_point(
        self, options: list[tuple[str, str]], legend: str, seen: dict[str, float], ranked: list[str]
    ) -> int:
        """Read the scale's ends and the question: 'hard' at the top means high contrast answers low; a statement
        to agree with ('easy to distinguish between the worst and middle ...') is about the pair it names."""
        top = options[-1][1].lower()
        text = legend.lower()
        if ranked and "worst and middle" in text:
            x = self._pair_contrast(ranked[-1], ranked[-2])
        elif ranked and "middle and best" in text:
            x = self._pair_contrast(ranked[1], ranked[0])
        elif ranked:
            x = self._pair_contrast(ranked[-1], ranked[0])
        elif len(seen) >= 2:
            low, high = sorted(seen.values())[0], sorted(seen.values())[-1]
            x = contrast(low, high)
        else:
            x = 0.5
        if "hard" in top:
            x = 1 - x
        return 1 + round(x * (len(options) - 1))

    def _explain(self, clip: Visible | None, seen: dict[str, float], ranked: list[str]) -> str:
        if clip is not None and seen:
            return clip.describe(max(seen, key=seen.__getitem__))
        if ranked:
            return f"{ranked[0]} did best in the clips and {ranked[-1]} worst."
        return "It looked that way in the clips."


def _played(clip: Visible) -> list[dict[str, Any]]:
    """The page's record of the clip loaded and played to its end; of a pair of reels, one reel after the other."""
    if isinstance(clip, VisibleReels):
        tags, lengths = [{"reel": k} for k in range(len(clip.reels))], list(clip.reel_s)
    else:
        tags, lengths = [{}], [clip.end_s]
    events = [{"type": "loaded", "t": 40} | tag for tag in tags]
    t = 800
    for tag, seconds in zip(tags, lengths, strict=True):
        events += [{"type": "play", "t": t} | tag, {"type": "ended", "t": t + int(seconds * 1000)} | tag]
        t += int(seconds * 1000)
    return events


def simulate(
    url: str,
    bundle_dir: str | Path,
    participants: int,
    *,
    noise: float = 0.5,
    seed: int = 0,
    inattentive: float = 0.0,
    first: int = 0,
    pilot_token: str = "",
) -> list[BotRun]:
    """Run `participants` bots against the server at `url`; bot k is `bot-SEED-k`, recorded as a bot.

    With the study's pilot token (in `url` as `?pilot=TOKEN`, the admin overview's pilot link, or given) the
    server does not hold a bot's answers for the clips' playing time, and the bots run one after another, fast.
    Without it each bot waits every clip's real playing time, as a participant must, and all bots run at once.

    `inattentive` is the share of bots that answer attention checks at random; `first` numbers the bots from
    there, so a second run against the same study adds new participants instead of resuming finished ones."""
    from concurrent.futures import ThreadPoolExecutor
    from urllib.parse import parse_qsl, urlsplit

    import httpx

    if participants < 1:
        raise ValueError(f"--participants must be at least 1, got {participants}")
    if noise < 0 or not 0 <= inattentive <= 1:
        raise ValueError("--noise must not be negative and --inattentive must be in [0, 1]")
    clips = ClipIndex(bundle_dir)
    observer = Observer(noise=noise)
    parts = urlsplit(url)
    link = dict(parse_qsl(parts.query))
    if pilot_token:
        link["pilot"] = pilot_token
    fast = bool(link.get("pilot"))
    base = f"{parts.scheme}://{parts.netloc}{parts.path.rstrip('/')}"

    def one(k: int) -> BotRun:
        rng = random.Random(f"{seed}:bot:{k}")
        attentive = rng.random() >= inattentive
        with httpx.Client(base_url=base, follow_redirects=True, timeout=60) as client:
            bot = Bot(
                client,
                clips,
                observer,
                rng,
                number=k,
                external_id=f"bot-{seed}-{k}",
                attentive=attentive,
                link=link,
                fast=fast,
            )
            return bot.take_study()

    numbers = range(first, first + participants)
    if fast:
        return [one(k) for k in numbers]
    with ThreadPoolExecutor(max_workers=min(participants, 64)) as pool:  # the waits overlap
        return list(pool.map(one, numbers))


def run_simulate(
    *, url: str, bundle: str | None, participants: int, noise: float, seed: int, inattentive: float, first: int
) -> int:
    """`foil simulate`: prints how many bots finished."""
    import os

    import httpx

    bundle = bundle or os.environ.get("FOIL_BUNDLE_DIR")
    if not bundle:
        raise ValueError(
            "give the study bundle the server serves (--bundle DIR or FOIL_BUNDLE_DIR): the bots "
            "look at its clips' summaries"
        )
    try:
        runs = simulate(
            url,
            bundle,
            participants,
            noise=noise,
            seed=seed,
            inattentive=inattentive,
            first=first,
            pilot_token=os.environ.get("FOIL_PILOT_TOKEN", ""),
        )
    except (httpx.HTTPError, BotError) as error:
        raise ValueError(f"the bots could not take the study at {url}: {error}") from None
    done = sum(run.completed for run in runs)
    print(
        f"{done} of {len(runs)} bots completed the study at {url} (noise {noise}, seed {seed}); "
        f"now run `foil report` on the server's database"
    )
    return 0 if done == len(runs) else 1
