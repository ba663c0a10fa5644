"""Ground truth with its uncertainty: two agents compared on the same test episodes (paired t-test), more episodes
for a pair the study's own do not decide (doubling, Bonferroni over the planned looks, at most 8 times as many),
and an undecided pair flagged in the manifest, the build's output and the gallery without naming a better robot."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from app.formats import MANIFEST_FORMAT, Manifest, manifest_json
from search.bundle.truth import ALPHA, LOOKS, compare_pairs, describe_close_pair, paired_comparison


class Recorded:
    """Hand-made per-episode rewards: episode i of ``agent`` is ``means[agent] + shared[i] + own noise``, the
    shared part the same for every agent (the starting state); the (agent, episodes) asked for are recorded."""

    def __init__(self, means: dict[str, float], shared: float = 0.0, noise: float = 1.0, seed: int = 0):
        self.means = means
        self.asked: list[list[tuple[str, int]]] = []
        rng = np.random.default_rng(seed)
        self.shared = shared * rng.standard_normal(100_000)
        self.own = {agent: noise * rng.standard_normal(100_000) for agent in means}

    def __call__(self, wanted):
        self.asked.append(sorted(wanted))
        return {(a, n): list(self.means[a] + self.shared[:n] + self.own[a][:n]) for a, n in wanted}


def test_the_paired_t_test_at_the_bonferroni_level():
    rng = np.random.default_rng(1)
    first, second = rng.normal(1.0, 1, 30), rng.normal(0.6, 1, 30)
    found = paired_comparison(("a", "b"), list(first), list(second))
    differences = first - second
    assert found.difference == pytest.approx(differences.mean())
    assert found.p == pytest.approx(min(1.0, LOOKS * stats.ttest_rel(first, second).pvalue))
    half = stats.t.ppf(1 - ALPHA / LOOKS / 2, 29) * differences.std(ddof=1) / math.sqrt(30)
    assert found.ci95 == pytest.approx((differences.mean() - half, differences.mean() + half))
    assert found.decided == (found.ci95[0] > 0 or found.ci95[1] < 0) == (found.p < ALPHA)
    assert found.episodes == 30 and found.agents == ("a", "b")


def test_pairing_by_starting_state_decides_what_separate_means_cannot():
    """Episodes differ far more from each other than the agents do: the paired differences still show it."""
    rewards = Recorded({"a": 1.0, "b": 0.0}, shared=20.0, noise=0.5)
    found = compare_pairs([("a", "b")], 50, rewards)[("a", "b")]
    assert found.decided and found.episodes == 50 and found.ci95[0] > 0
    first, second = (np.array(rewards({(agent, 50)})[agent, 50]) for agent in "ab")
    assert stats.ttest_ind(first, second).pvalue > 0.5  # as separate samples they look alike


def test_a_clearly_different_pair_decides_at_the_first_look():
    rewards = Recorded({"a": 3.0, "b": 0.0})
    found = compare_pairs([("a", "b")], 20, rewards)
    assert found[("a", "b")].decided and found[("a", "b")].episodes == 20 and found[("a", "b")].difference > 0
    assert rewards.asked == [[("a", 20), ("b", 20)]]


def test_identical_agents_stay_undecided_up_to_the_cap_and_never_beyond():
    rewards = Recorded({"a": 0.0, "b": 0.0}, shared=5.0, noise=0.0)  # the same reward in every episode
    found = compare_pairs([("a", "b")], 10, rewards)[("a", "b")]
    assert not found.decided and found.difference == 0 and found.ci95 == (0.0, 0.0) and found.p == 1.0
    assert found.episodes == 10 * 2 ** (LOOKS - 1) == 80  # the cap: 8 times the study's episodes
    assert [n for [(_, n), _] in rewards.asked] == [10, 20, 40, 80]


def test_agents_alike_in_distribution_stay_undecided_at_the_cap():
    rewards = Recorded({"a": 0.0, "b": 0.0}, shared=3.0, noise=1.0, seed=4)
    found = compare_pairs([("a", "b")], 25, rewards, looks=3)
    assert not found[("a", "b")].decided and found[("a", "b")].episodes == 100
    assert max(n for asked in rewards.asked for _, n in asked) == 100  # three looks: at most 4 times as many


def test_only_undecided_pairs_are_evaluated_again():
    rewards = Recorded({"lo": 0.0, "med": 0.45, "hi": 5.0}, seed=2)
    found = compare_pairs([("lo", "med"), ("med", "hi"), ("lo", "hi")], 20, rewards)
    assert found[("med", "hi")].episodes == found[("lo", "hi")].episodes == 20
    assert found[("lo", "med")].decided and found[("lo", "med")].episodes > 20
    assert all(set(agent for agent, _ in asked) == {"lo", "med"} for asked in rewards.asked[1:])
    assert compare_pairs([("lo", "med")], 20, rewards) == {("lo", "med"): found[("lo", "med")]}  # deterministic


def test_the_warning_names_agents_and_never_a_better_one():
    undecided = paired_comparison(("lo", "med"), [1.0, 3.0, 2.0, 5.0], [2.0, 1.0, 2.0, 4.0])
    line = describe_close_pair(undecided)
    assert line.startswith("warning: lo and med differ by less than the evaluation can decide")
    assert "4 paired episodes" in line and "coin toss" in line
    assert "better" not in line and "Robot" not in line


def test_a_manifest_without_close_pairs_is_written_as_before():
    plain = Manifest(format=MANIFEST_FORMAT, clips=[])
    assert "close_pairs" not in manifest_json(plain)
    pair = paired_comparison(("lo", "med"), [1.0, 3.0, 2.0, 5.0], [2.0, 1.0, 2.0, 4.0]).to_manifest()
    written = manifest_json(Manifest(format=MANIFEST_FORMAT, clips=[], close_pairs=[pair]))
    assert json.loads(written)["close_pairs"] == [pair]
    assert manifest_json(Manifest.model_validate_json(written)) == written


def wall_class(observations):
    """The wall's distance to three decimals, modulo 3: random from episode to episode, seen alike by every agent."""
    return np.floor(np.asarray(observations)[:, 1] * 1000).astype(int) % 3


def careful_a(observations):
    """Creeps (out of time before the wall: 6 points) in class 0, else runs into the wall (5 points)."""
    return np.where(wall_class(observations) == 0, 0.4, 0.5)[:, None]


def careful_b(observations):
    """Creeps in class 1: as good as ``careful_a`` on average, never better on the same episode."""
    return np.where(wall_class(observations) == 1, 0.4, 0.5)[:, None]


ADAPTER = "tests.gym.test_gym_clips:TrackAdapter"
CAREFUL_A, CAREFUL_B = "tests.bundle.test_close_pairs:careful_a", "tests.bundle.test_close_pairs:careful_b"
FAST, SLOW = "tests.gym.test_gym_clips:fast", "tests.gym.test_gym_clips:slow"
STUDY = f"""
[study]
id = "close"
title = "Which runner is better?"
platform = "none"
assignment = "balanced"
seed = 1
estimated_minutes = 2

[design]
schemes = ["nfirst"]
scheme_factor = "within"
scenarios = ["track.toml"]

[texts]
consent = "A test study."
instructions = "Watch the clips."

[completion]
code = "CLOSE"

[[parts]]
kind = "pairwise"
title = "Which is better?"
intro = "Watch each clip."
pairs = [["{CAREFUL_A}", "{CAREFUL_B}"], ["{FAST}", "{SLOW}"]]
questions = ["better"]

[questions.better]
type = "choose"
text = "Which is better?"

[build]
seed = 1

[build.eval]
episodes = 4
seed = 0

[build.render]
speed = 4.0
width = 480

[build.schemes.nfirst]
solver = "nfirst"
budget = 60
seed = 0

[[build.sets]]
parts = ["pairwise"]
schemes = ["nfirst"]
scenarios = ["track.toml"]
pairs = [["{CAREFUL_A}", "{CAREFUL_B}"], ["{FAST}", "{SLOW}"]]
"""


@pytest.mark.slow
def test_an_undecided_pair_is_flagged_in_the_manifest_the_output_and_the_gallery(tmp_path, monkeypatch):
    from search.bundle.build import build_bundle

    (tmp_path / "track.toml").write_text(f'adapter = "{ADAPTER}"\nseed = 3\n')
    (tmp_path / "study.toml").write_text(STUDY)
    monkeypatch.chdir(tmp_path)
    log = []
    manifest = json.loads(manifest_json(build_bundle("study.toml", "bundle", log=log.append)))

    [pair] = manifest["close_pairs"]  # fast and slow differ on every episode: decided on the study's 4
    assert pair["agents"] == [CAREFUL_A, CAREFUL_B] and not pair["decided"] and pair["episodes"] == 32
    assert pair["ci95"][0] < pair["difference"] < pair["ci95"][1] and pair["ci95"][0] < 0 < pair["ci95"][1]
    more = [line.split(": ")[0] for line in log if line.startswith("eval ") and " on " in line]
    assert more == [f"eval {agent} on {n} episodes" for n in (8, 16, 32) for agent in (CAREFUL_A, CAREFUL_B)]
    clip = next(c for c in manifest["clips"] if set(c["agents"]) == {CAREFUL_A, CAREFUL_B})
    labels = clip["labels"]
    assert clip["better"] == (CAREFUL_A if pair["difference"] > 0 else CAREFUL_B)
    about = [line for line in log if CAREFUL_A in line and not line.startswith("eval ")]
    assert about and any("differ by less than the evaluation can decide" in line for line in about)
    assert not any(label in line for line in about for label in labels)  # no robot named
    assert not any("better" in line for line in about)
    assert manifest["agents"][CAREFUL_A]["episodes"] == 4 and "episode_rewards" not in manifest["agents"][CAREFUL_A]

    # before anyone is recruited: the build says how many questions rest on the coin toss, and foil power expects
    # half the answers to that clip to be right (a clip that shows the better runner: 85%)
    assert "warning: pairwise part, scheme nfirst: 2 clips; 1 on a pair the evaluation could not decide" in "\n".join(
        log
    )
    from app.analysis.power import bundle_accuracies
    from app.survey.study import load_study

    shown = 0.85 if next(c for c in manifest["clips"] if FAST in c["agents"])["audit"]["shows"] == "better" else 0.5
    expected = bundle_accuracies("bundle", load_study("study.toml"), 0.85)
    assert expected == {"pairwise": {"nfirst": pytest.approx((0.5 + shown) / 2)}}

    gallery = (tmp_path / "bundle" / "index.html").read_text()
    assert "<h2>Close pairs</h2>" in gallery and f"{CAREFUL_A} and {CAREFUL_B} differ by less than" in gallery
    figure = next(f for f in gallery.split("<figure")[1:] if clip["id"] in f)
    assert "UNDECIDED" in figure and "(better)" not in figure
    other = next(f for f in gallery.split("<figure")[1:] if FAST in f)
    assert "(better)" in other and "UNDECIDED" not in other

    again = []  # the same seed: the same manifest, every evaluation reused
    assert json.loads(manifest_json(build_bundle("study.toml", "bundle", log=again.append))) == manifest
    assert all(line.endswith(": cached") for line in again if line.startswith("eval "))
