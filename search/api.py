"""What a world's author imports from Foil, in one import: ``from search.api import ...``.

The names are grouped by who uses them:

- **Adapter authors** bring a Gymnasium environment into Foil (docs/gym.md): they subclass `Adapter` and say what
  participants read in `Words`, and, where a clip is judged by a number it shows, its `Score`.
- **World authors** write a world of its own, in a package registered under the ``foil.domains`` entry point
  (tests/plugin/lineworld): a `Domain` with its abstract methods and `play` (docs/worlds.md).
  It says which names it ships (`Shipped`) and which files it takes (`Claim`), steps its agents in a coupled
  problem (`Problem`, with an `ActionPrior` over environment actions and the divergence reward's settings,
  `RewardConfig`) that it returns as a `Coupled`, reports endings as the outcome codes, writes `SUMMARY_FORMAT`
  summaries, plays test episodes as `Episode`s (Foil computes the evaluation from them), draws its clips with the
  toolkit's H.264 writer (`RenderOptions` in, `RenderResult` out, poster and sheet at `side_paths`) and says what a
  clip visibly shows in which words (`World`). Agents that can follow a leader, which Agent Disagreements and
  HIGHLIGHTS need, apply the follow-the-leader rule `Follow`.
- **Method authors** write a summary method of their own, in a module registered under the ``foil.solvers`` entry
  point: a `ProblemSearch` (a search of the coupled problem that spends a `Tracker`'s budget, playing rows from
  their start with `fresh` and `rollout`) passed to `register`.

The names stay where they are defined; this module only gathers them, so a world's imports do not follow Foil's
internal layout. Foil's own worlds (search/crowd, search/gym, search/highway) sit below it and import those
modules directly (tests/test_layers.py)."""

from app.formats import SUMMARY_FORMAT
from app.visible import Score, Words, World
from search.clips.render import RenderOptions, RenderResult, h264_writer, side_paths
from search.core.domain import Coupled, Domain
from search.core.evaluation import Episode
from search.core.outcomes import COLLISION, OUTCOME_NAMES, RUNNING, SUCCESS, TIMEOUT
from search.core.prior import ActionPrior
from search.core.problem import Problem
from search.core.rollout import Tracker, fresh, rollout
from search.core.world import Claim, Shipped
from search.gym.adapter import Adapter
from search.solvers.follow import Follow
from search.solvers.reward import RewardConfig
from search.solvers.solver import ProblemSearch, register

ADAPTER_AUTHORS = ("Adapter", "Score", "Words", "World")
WORLD_AUTHORS = (
    "COLLISION",
    "OUTCOME_NAMES",
    "RUNNING",
    "SUCCESS",
    "SUMMARY_FORMAT",
    "TIMEOUT",
    "ActionPrior",
    "Claim",
    "Coupled",
    "Domain",
    "Episode",
    "Follow",
    "Problem",
    "RenderOptions",
    "RenderResult",
    "RewardConfig",
    "Shipped",
    "h264_writer",
    "side_paths",
)
METHOD_AUTHORS = ("Problem", "ProblemSearch", "Tracker", "fresh", "register", "rollout")

__all__ = [
    "ActionPrior",
    "Adapter",
    "COLLISION",
    "Claim",
    "Coupled",
    "Domain",
    "Episode",
    "Follow",
    "OUTCOME_NAMES",
    "Problem",
    "ProblemSearch",
    "RUNNING",
    "RenderOptions",
    "RenderResult",
    "RewardConfig",
    "SUCCESS",
    "SUMMARY_FORMAT",
    "Score",
    "Shipped",
    "TIMEOUT",
    "Tracker",
    "Words",
    "World",
    "fresh",
    "h264_writer",
    "register",
    "rollout",
    "side_paths",
]
