"""The two files that pass between the offline side and the survey: summary.json and manifest.json.

Both sides read and write them through this module only; it imports nothing heavy, so the server (which never
imports the offline side) and the bundle builder share it. docs/formats.md describes every key.

- summary.json (``foil.summary/2``): one kept trajectory of a search, with everything needed to replay it
  exactly and to draw it. Written by each world's summary builder, read by ``foil verify``, the renderer, the
  bundle's audit, the server and the bots, always through ``load_summary`` or ``summary_of``, which read a
  ``foil.summary/1`` file (the crowd's words for the same keys) as the ``foil.summary/2`` it names.
- manifest.json (``foil.bundle/1``): a bundle's clips, each with its agents, on-screen labels, ground truth,
  audit and checksum (or, for a summary method that shows each agent on its own, one reel per agent), and the world
  they show (``app.visible.World``). Written by ``foil bundle``, read by the server and the bots.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Annotated, Any, Literal, NotRequired, TypedDict, cast

from pydantic import (
    AliasChoices,
    BaseModel,
    ConfigDict,
    Field,
    SerializerFunctionWrapHandler,
    field_validator,
    model_serializer,
    model_validator,
)
from typing_extensions import TypedDict as CheckedDict  # the one pydantic validates on Python 3.11

from app.visible import CROWD, World

SUMMARY_FORMAT = "foil.summary/2"
# foil.summary/1 named a step's keys and the closest distance in the crowd's words: read as the /2 keys they were
SUMMARY_V1 = "foil.summary/1"
V1_STEP_KEYS = {"humans": "other_positions", "robots": "agent_positions", "robot_actions": "agent_actions"}
V1_OUTCOME_KEYS = {"min_human_distance": "min_other_distance"}
MANIFEST_FORMAT = "foil.bundle/1"


def sha256_file(path: Path) -> str:
    """The hex sha256 of a file, read in blocks (clips can be large)."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


class SummaryAgent(TypedDict):
    name: str  # as given to foil search: lo, med, hi, a scripted policy or a checkpoint path
    source: str  # "scripted", or the file the network was loaded from


class SummaryStep(TypedDict):
    t: float  # simulated seconds after the step
    # the world's other movers, [[x, y], ...]; where each agent has its own world, one such list per agent
    other_positions: list[Any]
    agent_positions: list[list[float]]  # [x, y] per agent
    agent_actions: list[list[float]]  # the action each agent chose on this step
    scores: NotRequired[list[float]]  # each agent's visible score after the step, where its world shows one
    # where each agent has its own world and other_positions shows none of it: per agent, the sha256 of its world's
    # observation and state after the step (a Gymnasium adapter without others), so verify sees the whole world
    world_digests: NotRequired[list[str]]


class SummaryOutcome(TypedDict):
    event: Literal["running", "success", "collision", "timeout"]
    time: float | None  # when the event happened (null while running)
    path_length: float
    min_other_distance: float | None  # to the closest other mover, surface to surface (negative after a collision)


class Summary(TypedDict):
    format: str  # SUMMARY_FORMAT
    agents: list[SummaryAgent]
    scenario: dict[str, Any]  # the scenario with its complete world config
    solver: dict[str, Any]  # name, parameters, seed, budget, budget_used, search_reward, found_at_step, rank
    reward_parameters: dict[str, Any]
    env_actions: list[list[float]]  # per step, the flattened (humans x 2) environment action
    steps: list[SummaryStep]
    outcomes: list[SummaryOutcome]  # one per agent
    reward: float
    reward_terms: dict[str, Any]
    follow: NotRequired[dict[str, int]]  # {leader, steps}: every agent executed the leader's action on steps 1..steps
    window: NotRequired[list[int]]  # [first, last]: the states the clip shows


def summary_json(summary: Summary) -> str:
    """A summary's file text: the one way summaries are written, so equal summaries are equal files."""
    return json.dumps(summary, indent=1, allow_nan=False) + "\n"


def load_summary(path: str | Path) -> Summary:
    """A summary.json of either version as a current one, or an error that names the file and what is wrong."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"no summary file {str(path)!r}") from None
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not valid JSON: {error}") from None
    return summary_of(data, str(path))


def summary_of(data: Any, source: str = "summary") -> Summary:
    """A parsed summary of either version as a current one (a ``foil.summary/1`` one with its keys renamed, in
    their places), or an error naming ``source``: every summary is read through here, so no reader knows of /1."""
    if not isinstance(data, dict) or data.get("format") not in (SUMMARY_FORMAT, SUMMARY_V1):
        found = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise ValueError(
            f"{source}: not a summary (format {found!r}, expected {SUMMARY_FORMAT!r} or {SUMMARY_V1!r}); "
            "write it with `foil search`"
        )
    if data["format"] == SUMMARY_V1:
        data = _upgraded(data, source)
    return cast(Summary, data)  # checked as far as the server needs: a dict of this format


def _upgraded(data: dict[str, Any], source: str) -> dict[str, Any]:
    """A ``foil.summary/1`` summary as the ``foil.summary/2`` one it stands for: the same values under the /2 keys,
    each key where the /1 key was, so it writes as the file a current search would have written."""
    upgraded = dict(data, format=SUMMARY_FORMAT)
    for key, names in (("steps", V1_STEP_KEYS), ("outcomes", V1_OUTCOME_KEYS)):
        if key in data:
            entries = data[key]
            if not isinstance(entries, list) or not all(isinstance(entry, dict) for entry in entries):
                raise ValueError(f"{source}: {key} must be a list of objects")
            upgraded[key] = [{names.get(name, name): value for name, value in entry.items()} for entry in entries]
    return upgraded


class ClipVote(CheckedDict):
    """The representative solver's vote behind a clip: how many of the starting states it rolled out showed each
    agent as better (in the order of the clip's `agents`), how many neither, their summed weight (a viewer's expected
    vote per state, positive for the first agent) and the sign-flip test of those weights. An undecided (weak) vote
    may have chosen a clip of either agent as the better one. A manifest written before the weights has
    `sign_test_p` for `p` and no `weight`."""

    states: Annotated[int, Field(ge=0)]
    won: list[int]
    no_majority: Annotated[int, Field(ge=0)]
    p: Annotated[float, Field(ge=0, le=1, validation_alias=AliasChoices("p", "sign_test_p"))]
    decided: bool  # p below the solver's alpha over its looks (docs/search.md)
    weight: NotRequired[float]


class ClipAudit(BaseModel):
    """What the clip visibly shows against the ground truth (`app.visible.audit`), for researchers only; for a
    representative clip, the vote that chose it (absent for other clips and in manifests written before it)."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    shows: Literal["better", "worse", "tie"]
    why: str
    vote: ClipVote | None = None

    @model_serializer(mode="wrap")
    def _leaves_no_vote_out(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """An audit without a vote leaves `vote` out, so a manifest written before it reads and writes byte for
        byte as it did."""
        data: dict[str, Any] = handler(self)
        if self.vote is None:
            data.pop("vote", None)
        return data


class ManifestReel(BaseModel):
    """One agent's reel (HIGHLIGHTS): a video of its most important moments, cut from its own episodes."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    agent: str  # the real name, one of the clip's agents
    file: Annotated[str, Field(min_length=1)]  # relative to the bundle
    sha256: Annotated[str, Field(min_length=1)]
    poster: str = ""
    summaries: list[str] = []  # the summary.json of each segment, relative to the bundle, in the order shown


class ClipSpent(CheckedDict):
    """What making a clip cost: the simulator steps its search used and the seconds of video its question shows."""

    sim_steps: Annotated[int, Field(ge=0)]
    clip_seconds: Annotated[float, Field(ge=0)]  # for reels, both reels together


class ManifestClip(BaseModel):
    """One clip of a bundle: either a coupled clip (`file`, `sha256`: every agent in one video) or a pair of reels
    (`reels`: one video per agent, in the order of `agents`; then `file`, `sha256` and `summary` are empty). Fields
    after ``audit`` are for the researcher's gallery and analysis; the server needs only those before, and `reels`."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    id: str
    file: str = ""  # relative to the bundle
    sha256: str = ""
    scheme: str
    scenario: str
    agents: list[str]  # in on-screen order
    labels: list[str]  # each agent's on-screen name, e.g. "Robot 2"
    better: str  # the agent with the higher mean test reward: the ground truth
    summary: str = ""  # the summary.json the clip shows, relative to the bundle
    audit: ClipAudit | None = None
    poster: str = ""
    sheet: str = ""
    parts: list[str] = []  # survey parts the clip feeds: pairwise, ranking, example
    solver: str = ""
    reward: float | None = None  # the summary's divergence reward
    outcomes: list[dict[str, Any]] = []  # each agent's summary outcome, in on-screen order
    reels: list[ManifestReel] = []  # a pair of reels: one per agent, in the order of `agents`
    spent: ClipSpent | None = None  # what the clip cost; absent from manifests written before it was recorded

    @model_validator(mode="after")
    def _consistent(self) -> ManifestClip:
        if len(self.labels) != len(self.agents):
            raise ValueError("labels and agents must have the same length")
        if self.better not in self.agents:
            raise ValueError(f"better {self.better!r} is not one of its agents")
        if len(set(self.labels)) != len(self.labels):
            raise ValueError("labels must differ from each other")
        if self.reels:
            if [reel.agent for reel in self.reels] != self.agents:
                shown = [reel.agent for reel in self.reels]
                raise ValueError(f"reels must be one per agent in the order of agents {self.agents}, not {shown}")
            if self.file or self.sha256 or self.summary:
                raise ValueError("a clip of reels has no file, sha256 or summary of its own: each reel has them")
        elif not (self.file and self.sha256):
            raise ValueError("a clip needs its file and sha256, or one reel per agent")
        return self

    @model_serializer(mode="wrap")
    def _leaves_new_keys_out(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """A coupled clip leaves `reels` out and a clip without a cost `spent`, so a manifest written before they
        existed reads and writes byte for byte as it did."""
        data: dict[str, Any] = handler(self)
        if not self.reels:
            data.pop("reels", None)
        if self.spent is None:
            data.pop("spent", None)
        return data


class ClosePair(BaseModel):
    """Two agents the study's evaluation episodes could not tell apart, compared again on more test episodes, both
    from the same starting states (search/bundle/truth.py); for researchers. Undecided: the clips' `better` is the
    higher mean, within noise."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    agents: Annotated[list[str], Field(min_length=2, max_length=2)]
    difference: float  # mean reward of agents[0] minus agents[1] over the paired episodes
    ci95: Annotated[list[float], Field(min_length=2, max_length=2)]  # simultaneous over the planned looks
    p: Annotated[float, Field(ge=0, le=1)]  # paired t-test, Bonferroni-adjusted over the planned looks
    episodes: Annotated[int, Field(ge=2)]  # paired episodes of the last look
    decided: bool  # the interval excludes 0


class Manifest(BaseModel):
    model_config = ConfigDict(extra="ignore", frozen=True)

    format: str  # MANIFEST_FORMAT
    label_seed: int | None = None  # seeds the agent-to-robot-number mapping of the clips
    clips: list[ManifestClip]
    agents: dict[str, dict[str, Any]] = {}  # each agent's `foil eval --json` object
    # each agent's kind, checkpoint (path, sha256; a CrowdNav_DSRNN model's config and trained world) and the
    # full world it was evaluated and searched in (a clip's summary holds its search's exact world)
    sources: dict[str, dict[str, Any]] = {}
    files: dict[str, str] = {}  # every file of the bundle (relative path) -> sha256
    # per pair and fixed scenario: how representative it is of the task's distribution (researchers only)
    representativeness: list[dict[str, Any]] = []
    world: dict[str, Any] | None = None  # World.to_manifest() of the world the clips show; absent: the crowd
    close_pairs: list[ClosePair] = []  # pairs the study's episodes left undecided; absent when there are none

    @field_validator("world")
    @classmethod
    def _known_world(cls, world: dict[str, Any] | None) -> dict[str, Any] | None:
        shown = World.from_manifest(world)  # a world this server cannot speak of is refused at start-up
        return None if shown == CROWD else world  # the crowd's world is no world object: a crowd manifest has none

    @model_serializer(mode="wrap")
    def _leaves_empty_keys_out(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """A crowd manifest leaves `world` out, and one without close pairs `close_pairs`, so it reads byte for byte
        as it did before they had a key."""
        data: dict[str, Any] = handler(self)
        if self.world is None:
            data.pop("world", None)
        if not self.close_pairs:
            data.pop("close_pairs", None)
        return data

    def questions_at_risk(self) -> list[dict[str, Any]]:
        """Per survey part and scheme (in the clips' order): its clips, and how many of them rest on a pair the
        evaluation could not decide (the ground truth a coin toss), on a weak representative vote, or visibly show
        the worse agent as better (the audit). A researcher reads it before recruiting anyone."""
        undecided = {frozenset(pair.agents) for pair in self.close_pairs if not pair.decided}
        rows: dict[tuple[str, str], dict[str, Any]] = {}
        for clip in self.clips:
            pairs = {frozenset((a, b)) for i, a in enumerate(clip.agents) for b in clip.agents[i + 1 :]}
            vote = clip.audit.vote if clip.audit is not None else None
            for part in clip.parts:
                if part == "example":
                    continue
                row = rows.setdefault(
                    (part, clip.scheme),
                    {"part": part, "scheme": clip.scheme, "clips": 0, "undecided": 0, "weak_vote": 0, "misleading": 0},
                )
                row["clips"] += 1
                row["undecided"] += bool(pairs & undecided)
                row["weak_vote"] += vote is not None and not vote["decided"]
                row["misleading"] += clip.audit is not None and clip.audit.shows != "better"
        return list(rows.values())

    def shown_world(self) -> World:
        return World.from_manifest(self.world)


def manifest_json(manifest: Manifest) -> str:
    """A manifest's file text: the one way manifests are written."""
    return json.dumps(manifest.model_dump(mode="json"), indent=1) + "\n"
