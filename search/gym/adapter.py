"""The adapter a researcher writes to compare agents in their own Gymnasium environment.

An adapter says four things Foil cannot guess: how to make the environment, what the environment action is and
how it acts on the world (never on the agents), where an agent is (for the state divergence), and how an
episode's end reads as Foil's events. Copy this template and fill it in (docs/gym.md walks through it)::

    from search.gym.adapter import Adapter

    class PushTheObstacle(Adapter):
        env_action_shape = (2,)   # every entry in [-1, 1]; the searches sample and perturb in that box
        dt = 0.1                  # simulated seconds per step, for event times and clips

        def make(self, render=False):                       # render: frames from env.render() for clips
            return gymnasium.make("MyEnv-v0", render_mode="rgb_array" if render else None, **self.settings)

        def apply(self, env, action):
            env.unwrapped.obstacle_velocity = 0.5 * action   # the world moves; the agent's own state is untouched

        def position(self, env):
            return env.unwrapped.agent_xy                   # where the agent is, as a vector

        def outcome(self, terminated, truncated, info, reward, env):  # optional: the default reads info["crashed"]
            ...

``snapshot_env``/``restore_env`` may be overridden with a faster state get/set where the environment has one, and
must be where it cannot be deep-copied; by default a snapshot is a deep copy of the environment (wrappers, the
unwrapped environment and its random generator). ``others`` (optional) lists what else of the world a summary
records; without it a summary records a digest of each instance's observation and state (`search.gym.world_state`).

Clips need nothing more: the generic renderer draws the environment's own ``render()`` frames. Optional hooks
(``view_settings``, ``record``, ``mark_agent``, ``crash_point``, ``caption``, ``status_words``, at the class's end)
say what it cannot know; ``renderer`` names a renderer of the adapter's own.
"""

from __future__ import annotations

import copy
import inspect
import os
import sys
from abc import ABC, abstractmethod
from collections.abc import Callable
from importlib import import_module
from typing import Any, ClassVar, Protocol

import numpy as np

from app.visible import Score, Words, World
from search.core.evaluation import EVENTS


class Adapter(ABC):
    """Base class of environment adapters; ``settings`` (a JSON-able dict) are the scenario's own settings.

    ``rule`` and ``words`` are what a clip visibly shows and how participants read it (`app.visible.World`):
    "goal" where an agent should reach something (sooner is better), "survival" where it should last (a car
    that crashes later did better); the words name the agents' outcomes on the survey's pages, in the clip audit
    and the report. ``score`` (an `app.visible.Score`, with ``measure``) is a quantity each view shows as it
    changes: "score" judges a world of reward alone by it (no goal, no crash), and in the others it breaks ties.
    Foil never guesses one: only an adapter that declares it has one."""

    env_action_shape: tuple[int, ...] = ()
    dt: float = 1.0
    domain: str = "gym"
    rule: str = "goal"
    words: Words = Words()  # the words of agents and outcomes in general, in the agent's word
    score: Score | None = None  # the visible score each view shows, read by ``measure`` after each step
    # where ``score`` declares one, ``measure(self, env) -> float`` reads its value in ``env`` after the reset and
    # each step (what the view shows: the distance travelled, the error from a set point); checked at load
    measure: Callable[[Any], float]

    def __init__(self, settings: dict | None = None):
        self.settings = dict(settings or {})

    @abstractmethod
    def make(self, render: bool = False):
        """A fresh environment (gymnasium.Env); with ``render``, one whose ``render()`` returns RGB frames."""

    @abstractmethod
    def apply(self, env, action: np.ndarray) -> None:
        """Act on the world with an environment action (shape ``env_action_shape``, entries in [-1, 1]) before
        the agent's step. Must never change the agent itself: the agents are what is compared."""

    @abstractmethod
    def position(self, env) -> np.ndarray:
        """Where the agent is, as a float vector: the state divergence compares these between agents."""

    def outcome(self, terminated: bool, truncated: bool, info: dict, reward: float = 0.0, env: Any = None) -> str:
        """Foil's event for an episode that ended: ``success``, ``collision`` (a crash or any failure) or
        ``timeout``, from the last step's flags, ``info``, ``reward`` and the environment after it (a world whose
        ``info`` is empty may read success from the reward). Default: a crash (``info["crashed"]``) or any other
        termination is a collision unless ``info["is_success"]`` says it reached its goal; a truncation is a
        timeout. An override with the older signature ``(terminated, truncated, info)`` still works."""
        if terminated:
            return "success" if info.get("is_success") and not info.get("crashed") else "collision"
        return "timeout"

    def world(self) -> World:
        return World(domain=self.domain, rule=self.rule, words=self.words, score=self.score)

    def snapshot_env(self, env):
        """A copy of ``env`` that later steps of ``env`` cannot change."""
        try:
            return copy.deepcopy(env)
        except (TypeError, copy.Error, RecursionError) as error:
            raise ValueError(
                f"{type(self).__name__}: Foil cannot deep-copy the environment ({type(error).__name__}: {error}); it "
                "copies it to branch searches and replay summaries. Define snapshot_env(env) and restore_env(saved) "
                "on the adapter with the environment's own state get/set (docs/gym.md, 'Environments that cannot be "
                "copied')"
            ) from None

    def restore_env(self, saved):
        """An environment in the saved state; ``saved`` itself must stay usable for further restores."""
        return copy.deepcopy(saved)

    def agent_names(self) -> list[str]:
        """The agents this domain ships (default: none)."""
        return []

    def agent_file(self, name: str):
        """The model file of a shipped agent ``name``, or None when it is not one."""
        return None

    def others(self, env) -> list:
        """What else a clip or a summary shows of the world, as [[x, y], ...] (default: nothing). An adapter that
        defines it has its summaries record it each step in place of a digest of the world's state, so it should
        show whatever an environment action changes."""
        return []

    # Clips (search/gym/clips.py): what the generic renderer cannot know. Every hook has a default, so an adapter
    # that defines none still renders: the environment's own frames, a label and status under each.

    renderer: str | None = None  # "module:function" with render_gym's signature: the adapter's own renderer
    status_words: ClassVar[dict[str, str]] = {
        "success": "succeeded",
        "collision": "failed",
        "timeout": "out of time",
        "running": "running",
    }  # the status panel's words for each outcome, and for an episode still going at the clip's end

    def view_settings(self, width_px: int) -> dict:
        """Settings merged over the scenario's for the rendering environment (screen size, zoom), for a view at
        most ``width_px`` wide; the dynamics must not change. Default none: the environment's frames, scaled."""
        return {}

    def record(self, env, capture) -> int:
        """Called once per agent after the reset, before the first frame: arrange for ``capture()`` after each
        frame the environment simulates inside a step (smoother motion than one frame a step); returns the frames
        a step shows, the one after it included. Default 1."""
        return 1

    def mark_agent(self, env, rgb: tuple[int, int, int]) -> None:
        """Paint the agent in its robot's colour before each frame, and nothing else in a robot colour. Default
        nothing: the label under the view names it."""
        return None

    def crash_point(self, env) -> tuple[float, float] | None:
        """Where a crash marker goes in the view of the episode's end, as fractions of the view's width and height
        from its top left; None for no marker. Default the view's centre."""
        return (0.5, 0.5)

    def caption(self, env) -> str:
        """A short text beside the agent's label, read after each step (a speed, a score). Default none."""
        return ""


class Ending(Protocol):
    def __call__(self, terminated: bool, truncated: bool, info: dict, reward: float, env: Any) -> str: ...


def ending(adapter: Adapter) -> Ending:
    """The adapter's ``outcome`` as a call with the step's reward and environment, checked once: an override with
    the older ``(terminated, truncated, info)`` is called without them; the event must be one of ``EVENTS``."""
    parameters = inspect.signature(adapter.outcome).parameters.values()
    positional = [p for p in parameters if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    takes_all = len(positional) >= 5 or any(p.kind is p.VAR_POSITIONAL for p in parameters)
    if not takes_all and len(positional) != 3:
        raise ValueError(
            f"{type(adapter).__name__}.outcome takes {len(positional)} arguments: define it as "
            "outcome(self, terminated, truncated, info, reward, env)"
        )

    def read(terminated: bool, truncated: bool, info: dict, reward: float, env: Any) -> str:
        event = (
            adapter.outcome(terminated, truncated, info, reward, env)
            if takes_all
            else adapter.outcome(terminated, truncated, info)
        )
        if event not in EVENTS:
            raise ValueError(f"adapter outcome {event!r}: use one of {EVENTS}")
        return event

    return read


def load_adapter(spec: str, settings: dict | None = None) -> Adapter:
    """An adapter from ``module:Class`` and its settings."""
    if ":" not in spec:
        raise ValueError(f"adapter {spec!r}: give it as module:Class, e.g. search.highway.adapter:HighwayAdapter")
    cls = import_attribute(spec, "adapter")
    if not (isinstance(cls, type) and issubclass(cls, Adapter)):
        raise ValueError(f"adapter {spec!r} is not a subclass of search.gym.adapter.Adapter")
    adapter = cls(settings)
    shape = tuple(adapter.env_action_shape)
    if not shape or int(np.prod(shape)) < 1:
        raise ValueError(f"adapter {spec!r} defines no environment action: set env_action_shape, e.g. (2,)")
    if adapter.score is not None and not callable(getattr(adapter, "measure", None)):
        raise ValueError(
            f"adapter {spec!r} declares the visible score {adapter.score.name!r} but not how to read it: define "
            "measure(self, env) -> float (docs/gym.md, 'A visible score')"
        )
    adapter.world()  # a rule without what it judges by is refused here, before any search
    return adapter


def import_attribute(spec: str, what: str):
    """The attribute ``module:attribute`` names. The working directory is on the import path, as for
    ``python -m``, so a researcher's module beside their scenario files imports without installing it."""
    module_name, _, attribute = spec.partition(":")
    if os.getcwd() not in sys.path:
        sys.path.append(os.getcwd())
    try:
        return getattr(import_module(module_name), attribute)
    except (ImportError, AttributeError) as error:
        raise ValueError(
            f"cannot load {what} {spec!r}: {error} (a module is imported from the working directory or the Python path)"
        ) from None
