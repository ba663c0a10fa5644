"""A visible score: a world of reward alone (no goal, no crash, every episode runs to its time limit), written here,
is judged by what its clips show on screen. A point drifts on a line in a wind the environment action strengthens;
the steady agent holds it near its set point, the idle one lets it drift. With the score declared its
representative clips show the steady agent as better, the audit agrees and the bots' observer sees it; without it
every clip is a tie, as before. Then each way a clip sums a score, and the score as a tie-breaker in a goal world.
"""

from __future__ import annotations

import json
import random

import gymnasium
import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

from app.analysis.bots import Bot, ClipIndex
from app.store.database import migrate
from app.survey.kinds import pilot_token
from app.visible import Observer, VisibleClip, World, audit
from app.web.main import create_app
from app.web.settings import ServerSettings
from search.api import Adapter, Score
from search.cli import main
from search.clips.render import RenderOptions, fit_text, text_width
from search.gym.clips import GymClipRenderer

STEADY, IDLE = "tests.gym.test_visible_score:steady", "tests.gym.test_visible_score:idle"
HOLD = Score("offset", "m", "higher", "band", band=(-0.2, 0.2), digits=2)


class Drift(gymnasium.Env):
    """A point on a line, 0 its set point, blown by a wind of 0.5 m/s that the environment action turns between 0
    and 1 m/s; the agent pushes back at up to 1.2 m/s. The reward is minus the distance from the set point; twenty
    steps, then a truncation. Drawn 96 px wide and 48 px tall."""

    metadata = {"render_modes": ["rgb_array"]}
    dt, steps_limit = 0.25, 20

    def __init__(self, render_mode=None):
        self.render_mode = render_mode
        self.action_space = gymnasium.spaces.Box(-1.0, 1.0, (1,), dtype=np.float64)
        self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (1,), dtype=np.float64)
        self.gust = 0.0

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.x, self.steps = float(self.np_random.uniform(-0.15, 0.15)), 0
        return np.array([self.x]), {}

    def step(self, action):
        self.x += self.dt * (1.2 * float(np.clip(action[0], -1.0, 1.0)) + 0.5 + 0.5 * self.gust)
        self.steps += 1
        return np.array([self.x]), -abs(self.x), False, self.steps >= self.steps_limit, {}

    def render(self):
        frame = np.full((48, 96, 3), 235, dtype=np.uint8)
        frame[:, 48] = (150, 150, 150)  # the set point
        column = int(np.clip(48 + 20 * self.x, 2, 93))
        frame[18:30, column - 2 : column + 3] = (40, 40, 40)
        return frame


class DriftAdapter(Adapter):
    """The template filled in for a world of reward alone, and its visible score: seconds within 0.2 m of the set
    point."""

    env_action_shape = (1,)
    dt = Drift.dt
    rule = "score"
    score: Score | None = HOLD

    def make(self, render=False):
        return Drift(render_mode="rgb_array" if render else None)

    def apply(self, env, action):
        env.unwrapped.gust = (float(action[0]) + 1) / 2

    def position(self, env):
        return np.array([env.unwrapped.x])

    def measure(self, env):
        return env.unwrapped.x


class UnscoredDriftAdapter(DriftAdapter):
    """The same world without its score: Foil guesses none, so no clip shows a difference."""

    rule = "goal"
    score = None


def steady(observations):
    """Pushes back towards the set point."""
    return np.clip(-6.0 * observations, -1.0, 1.0)


def idle(observations):
    """Lets the wind blow it away."""
    return np.zeros((len(observations), 1))


STUDY = f"""
[study]
id = "drift"
title = "Which agent holds its point better?"
platform = "none"
assignment = "balanced"
seed = 1
estimated_minutes = 2

[design]
schemes = ["representative"]
scheme_factor = "within"
scenarios = ["drift-starts.toml"]

[texts]
consent = "A test study."
instructions = "Watch the clips."

[completion]
code = "DRIFT"

[[parts]]
kind = "pairwise"
title = "Which is better?"
intro = "Watch each clip."
pairs = [["{STEADY}", "{IDLE}"]]
questions = ["better"]

[questions.better]
type = "choose"
text = "Which is better?"

[build]
seed = 1

[build.eval]
episodes = 2
seed = 0

[build.render]
speed = 4.0
width = 480

[build.schemes.representative]
solver = "representative"
budget = 400
seed = 0
settings = {{ states = 4, pushes = 2 }}
reward = {{ horizon_steps = 20 }}

[[build.sets]]
parts = ["pairwise"]
schemes = ["representative"]
scenarios = ["drift-starts.toml"]
agents = ["{STEADY}", "{IDLE}"]
"""


@pytest.fixture
def world(tmp_path, monkeypatch):
    for name, adapter in (("drift", "DriftAdapter"), ("unscored", "UnscoredDriftAdapter")):
        spec = f"tests.gym.test_visible_score:{adapter}"
        (tmp_path / f"{name}-starts.toml").write_text(f'adapter = "{spec}"\n[distribution]\nseeds = [0, 100]\n')
    (tmp_path / "study.toml").write_text(STUDY)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def representative(world, scenario: str) -> tuple[dict, list]:
    args = ["--budget", "400", "--top-k", "2", "--out", scenario, "--quiet", "--reward", "horizon_steps=20"]
    args += ["--solver", "representative", "--set", "states=4", "--set", "pushes=2"]
    assert main(["search", "--agents", f"{STEADY},{IDLE}", "--scenario", f"{scenario}-starts.toml", *args]) == 0
    summaries = sorted((world / scenario).glob("summary-*.json"))
    assert summaries and main(["verify", *map(str, summaries)]) == 0
    return json.loads((world / scenario / "run.json").read_text())["vote"], summaries


def test_a_world_of_reward_alone_is_judged_by_its_visible_score(world):
    vote, summaries = representative(world, "drift")
    assert vote["direction"] == 1 and vote["for_first"] > 0 and vote["for_second"] == 0  # the steady agent
    summary = json.loads(summaries[0].read_text())
    assert all(len(step["scores"]) == 2 for step in summary["steps"])
    clip = VisibleClip.of_summary(summary, [STEADY, IDLE], ["Agent 1", "Agent 2"], DriftAdapter().world())
    verdict = audit(clip, "Agent 1")
    assert verdict["shows"] == "better", verdict
    assert verdict["why"].startswith("Agent 1 kept its offset within -0.20 to 0.20 for ")


def test_eval_reports_each_agents_visible_score(world, capsys):
    for agent in (STEADY, IDLE):
        assert main(["eval", agent, "--scenario", "drift-starts.toml", "--episodes", "4", "--json"]) == 0
    steady_result, idle_result = (json.loads(line) for line in capsys.readouterr().out.splitlines())
    assert steady_result["score"]["name"] == "offset" and steady_result["score"]["summed"] == "band"
    assert steady_result["score"]["mean"] > 4.0 > idle_result["score"]["mean"]  # seconds of 5 within the band
    low, high = steady_result["score"]["ci95"]
    assert low <= steady_result["score"]["mean"] <= high
    assert main(["eval", STEADY, "--scenario", "drift-starts.toml", "--episodes", "4"]) == 0
    assert " s of offset within its band (" in capsys.readouterr().out


def test_without_the_score_every_clip_is_a_tie_as_before(world):
    vote, summaries = representative(world, "unscored")
    assert vote["for_first"] == vote["for_second"] == 0
    assert vote["selection"] == "no visible contrast anywhere: the first state without pushes"
    assert "scores" not in json.loads(summaries[0].read_text())["steps"][0]


def test_the_bundle_audits_and_the_bots_see_the_better_agent(world, capsys):
    assert main(["bundle", "study.toml", "--out", "bundle"]) == 0
    manifest = json.loads((world / "bundle" / "manifest.json").read_text())
    assert manifest["world"]["rule"] == "score" and manifest["world"]["score"] == HOLD.to_manifest()
    [clip] = manifest["clips"]
    assert clip["audit"]["shows"] == "better"
    better = clip["labels"][clip["agents"].index(STEADY)]
    database = f"sqlite:///{world / 'survey.sqlite3'}"
    migrate(database)
    settings = ServerSettings(
        bundle_dir=world / "bundle", study_file=world / "bundle" / "study.toml", database_url=database
    )
    clips, observer, picks = ClipIndex(world / "bundle"), Observer(), []
    app = create_app(settings)
    with TestClient(app, follow_redirects=True) as client:
        link = {"pilot": pilot_token(app.state.context.db, "drift")}  # as `foil simulate` with FOIL_PILOT_TOKEN
        for k in range(12):  # `foil simulate`'s bots, one after another, without waiting out each clip
            client.cookies.clear()  # each a participant of its own
            bot = Bot(client, clips, observer, random.Random(k), number=k, external_id=f"b{k}", link=link, fast=True)
            run = bot.take_study()
            assert run.completed
            picks += [answer["value"] == better for answer in run.answers if answer["question"] == "better"]
    assert len(picks) == 12 and sum(picks) >= 10  # far above chance (6)


def test_each_view_shows_its_score_beside_its_label(world):
    """The caption under each view is the score as the clip sums it, inside the view's band."""
    _, summaries = representative(world, "drift")
    summary = json.loads(summaries[0].read_text())
    renderer = GymClipRenderer(summary, [1, 2], RenderOptions(width=480))
    scene = renderer.scene
    last = [scene.caption(k, scene.end_time) for k in range(2)]
    seconds = [VisibleClip.of_summary(summary, [STEADY, IDLE], ["a", "b"], DriftAdapter().world()).summed]
    for k, text in enumerate(last):
        assert text == f"{seconds[0][k]:.1f} s in band"
    lay = renderer.layout
    beside = lay.panel - lay.text * 3.8 - text_width("Agent 2", lay.text, True)  # the line right of the label
    assert all(fit_text(text, lay.text, beside) == (text, lay.text) for text in last)  # whole, full size
    image = renderer.draw(renderer.frames[-1])
    assert isinstance(image, Image.Image) and image.width == 480


@pytest.mark.parametrize(
    "score, values, summed",
    [
        (Score("distance", "m", "higher", "final", span=5.0), [1.0, 2.04, 3.06], 3.1),
        (Score("error", "", "lower", "mean", digits=2, span=0.5), [0.1, 0.2, 0.6], 0.3),
        (
            Score("error", "", "higher", "band", band=(-0.1, 0.1), digits=2),
            [0.0, 0.05, 0.3, -0.1],
            0.8,
        ),  # 0.75 s, shown
    ],
)
def test_each_way_a_clip_sums_its_score(score, values, summed):
    assert score.of(values, 0.25) == pytest.approx(summed)
    assert Score.from_manifest(json.loads(json.dumps(score.to_manifest()))) == score


@pytest.mark.parametrize(
    "score, summed, sentence",
    [
        (Score("speed", "km/h", "higher", "mean", digits=0, span=20.0), 72.0, "had a mean speed of 72 km/h"),
        (Score("distance", "m", "higher", "final", span=5.0), 11.0, "ended with a distance of 11.0 m"),
        (Score("error", "", "lower", "final", digits=2, span=0.5), 0.04, "ended with an error of 0.04"),
        (HOLD, 0.8, "kept its offset within -0.20 to 0.20 for 0.8 seconds"),
    ],
)
def test_each_way_a_clip_sums_its_score_reads_as_a_sentence_after_the_label(score, summed, sentence):
    assert score.describe(summed) == sentence
    ended = ({"event": "success", "time": 10.0}, {"event": "success", "time": 10.0})
    clip = VisibleClip(("Car 3", "Car 4"), ended, (0.0, 0.0), 20.0, world=World(score=score), summed=(summed, 0.0))
    assert clip.describe("Car 3") == f"Car 3 succeeded after 10.0 seconds; it {sentence}."


def test_a_score_reads_as_a_viewer_reads_it():
    error = Score("error", "", "lower", "mean", digits=1, span=1.0)
    world = World(domain="gym", rule="score", score=error)
    clip = VisibleClip(("A", "B"), ({}, {}), (0.0, 0.0), 5.0, world=world, summed=(0.2, 0.5))
    assert clip.scores(Observer()) == {"A": pytest.approx(-0.2), "B": pytest.approx(-0.5)}
    assert audit(clip, "A")["shows"] == "better" and audit(clip, "B")["shows"] == "worse"
    assert audit(VisibleClip(("A", "B"), ({}, {}), (0.0, 0.0), 5.0, world=world, summed=(0.2, 0.2)), "A")["shows"] == (
        "tie"  # sums that read the same on screen
    )
    assert error.caption(0.44, [0.1, 0.3], 0.25) == "0.2 mean error"
    assert HOLD.caption(0.3, [0.0, 0.1, 0.3], 0.5) == "1.0 s in band"
    assert World.from_manifest(world.to_manifest()) == world
    assert "score" not in World(domain="gym", rule="goal").to_manifest()


def test_the_score_breaks_a_tie_of_outcomes_in_a_goal_world():
    """Two arrivals within a fraction of a second look the same by the goal rule; the distance each covered on the
    way (a score shown on screen) tells them apart, and where it reads the same they stay a tie."""
    arrivals = ({"event": "success", "time": 10.0}, {"event": "success", "time": 10.3})
    distance = Score("distance", "m", "lower", "final", span=2.0)
    plain, scored = World(domain="gym"), World(domain="gym", score=distance)
    assert audit(VisibleClip(("A", "B"), arrivals, (0.0, 0.0), 20.0, world=plain), "B")["shows"] == "tie"
    shorter = VisibleClip(("A", "B"), arrivals, (0.0, 0.0), 20.0, world=scored, summed=(12.0, 11.0))
    verdict = audit(shorter, "B")
    assert verdict["shows"] == "better" and "it ended with a distance of 11.0 m" in verdict["why"]
    same = VisibleClip(("A", "B"), arrivals, (0.0, 0.0), 20.0, world=scored, summed=(11.0, 11.0))
    assert audit(same, "B")["shows"] == "tie"
    crash = ({"event": "collision", "time": 3.0}, arrivals[1])
    assert (
        audit(VisibleClip(("A", "B"), crash, (0.0, 0.0), 20.0, world=scored, summed=(1.0, 30.0)), "B")["shows"]
        == "better"
    )  # a clear difference of outcomes is never overruled by the score


@pytest.mark.parametrize(
    "settings, message",
    [
        (dict(summed="sum"), "summed must be one of"),
        (dict(summed="final"), "needs span > 0"),
        (dict(summed="band"), "needs band=\\(low, high\\)"),
        (dict(summed="band", band=(0.0, 1.0), span=1.0), "leave span unset"),
        (dict(better="more", span=1.0), "better must be 'higher' or 'lower'"),
    ],
)
def test_a_score_that_cannot_be_read_is_refused_with_the_fix(settings, message):
    with pytest.raises(ValueError, match=message):
        Score("error", **settings)


def test_an_adapter_must_say_how_to_read_its_score():
    from search.gym.adapter import load_adapter

    with pytest.raises(ValueError, match="define measure"):
        load_adapter("tests.gym.test_visible_score:Unread")
    with pytest.raises(ValueError, match="declares no visible score"):
        World(domain="gym", rule="score")


class Unread(DriftAdapter):
    measure = None  # type: ignore[assignment]  # a score declared with nothing to read it


def test_the_fast_rollouts_see_each_clips_score_as_its_summary_does(world):
    """The representative vote and the representativeness check read each rollout's score from the problem; the
    interface's default builds each rollout's summary. Both must see the same clips."""
    from search.core.domain import domain_for
    from tests.support.played import checked_rollouts

    domain = domain_for([STEADY, IDLE], "drift-starts.toml")
    states = domain.draw_states("drift-starts.toml", {}, np.random.default_rng(0), 4)
    fast = checked_rollouts(domain, [STEADY, IDLE], states, 20, 3).pair(0, 1)[0]
    assert (fast.contrast > 0).all()  # the steady agent holds its point in every rollout, pushed or not


def test_a_pair_of_reels_is_judged_by_each_agents_score_over_its_moments():
    """HIGHLIGHTS shows each agent on its own: each segment's score is its leader's, summed over its window."""
    from app.visible import VisibleReels

    def segment(leader: int, offsets: list[float]) -> dict:
        steps = [{"t": 0.25 * (i + 1), "scores": [x, x]} for i, x in enumerate(offsets)]
        return {"agents": [{"name": "a"}, {"name": "b"}], "steps": steps, "outcomes": [{}, {}], "window": [1, 4]}

    held, drifted = [0.0, 0.1, 0.1, 0.0], [0.1, 0.3, 0.5, 0.7]
    reels = [[segment(0, held) | {"follow": {"leader": 0}}], [segment(1, drifted) | {"follow": {"leader": 1}}]]
    shown = VisibleReels.of_summaries(reels, ["Agent 1", "Agent 2"], DriftAdapter().world())
    assert [reel[0].summed for reel in shown.reels] == [(0.8,), (0.0,)]  # 3 steps after the window's first state
    assert audit(shown, "Agent 1")["shows"] == "better"
    assert "kept its offset within -0.20 to 0.20 for 0.8 seconds" in shown.describe("Agent 1")
