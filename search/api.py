"""What a world's author imports from Foil, in one import: ``from search.api import ...``.

Two kinds of code use it. An adapter brings a Gymnasium environment into Foil (docs/gym.md): it subclasses
`Adapter` and says what participants read in `Words`. A world of its own, in a package registered under the
``foil.domains`` entry point (tests/plugin/lineworld), implements `Domain`: it says which names it ships
(`Shipped`) and which files it takes (`Claim`), steps its agents in a coupled problem (`Problem`, with an
`ActionPrior` over environment actions and the divergence reward's settings, `RewardConfig`), reports their
endings as the outcome codes, writes `SUMMARY_FORMAT` summaries through `Coupled`, draws its clips with the
toolkit's H.264 writer (`RenderOptions` in, `RenderResult` out, poster and sheet at `side_paths`) and says what a
clip visibly shows in which words (`World`), with a `Score` where a clip is judged by a number it shows. A summary
method of its own, in a module registered under the ``foil.solvers`` entry point, is a `ProblemSearch` (a search
of the coupled problem that spends a `Tracker`'s budget, playing rows from their start with `fresh` and
`rollout`) passed to `register`.

The names stay where they are defined; this module only gathers them, so a world's imports do not follow Foil's
internal layout. Foil's own worlds (search/crowd, search/gym, search/highway) sit below it and import those
modules directly (tests/test_layers.py)."""

from app.formats import SUMMARY_FORMAT
from app.visible import Score, Words, World
from search.clips.render import RenderOptions, RenderResult, h264_writer, side_paths
from search.core.outcomes import COLLISION, OUTCOME_NAMES, RUNNING, SUCCESS, TIMEOUT
from search.core.world import Claim, Shipped
from search.gym.adapter import Adapter
from search.solvers.domain import Coupled, Domain
from search.solvers.prior import ActionPrior
from search.solvers.problem import Problem
from search.solvers.reward import RewardConfig
from search.solvers.rollout import Tracker, fresh, rollout
from search.solvers.solver import ProblemSearch, register

__all__ = [
    "COLLISION",
    "OUTCOME_NAMES",
    "RUNNING",
    "SUCCESS",
    "SUMMARY_FORMAT",
    "TIMEOUT",
    "ActionPrior",
    "Adapter",
    "Claim",
    "Coupled",
    "Domain",
    "Problem",
    "ProblemSearch",
    "RenderOptions",
    "RenderResult",
    "RewardConfig",
    "Score",
    "Shipped",
    "Tracker",
    "Words",
    "World",
    "fresh",
    "h264_writer",
    "register",
    "rollout",
    "side_paths",
]
