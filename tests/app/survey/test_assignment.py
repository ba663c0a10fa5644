"""Balanced assignment: permuted blocks, concurrent arrivals, concurrent first visits of one person."""

from __future__ import annotations

import random
import threading
from collections import Counter

from fastapi.testclient import TestClient

from app.store.models import Participant
from app.survey.assignment import condition_for_slot, conditions
from app.survey.plan import build_plan
from app.survey.screens import Pairwise, Ranking
from app.survey.study import load_study
from tests.support.survey import PAPER_STUDY, FormReader, start, stored


def test_every_block_holds_each_condition_once():
    for n in (1, 2, 4, 6):
        for block in range(20):
            got = [condition_for_slot(seed=7, n_conditions=n, slot=block * n + i) for i in range(n)]
            assert sorted(got) == list(range(n))
    orders = {tuple(condition_for_slot(seed=7, n_conditions=4, slot=b * 4 + i) for i in range(4)) for b in range(20)}
    assert len(orders) > 1  # blocks are shuffled, not a fixed rotation
    assert condition_for_slot(seed=7, n_conditions=4, slot=13) == condition_for_slot(seed=7, n_conditions=4, slot=13)


def test_paper_conditions_are_scheme_order_times_scenario_order():
    study = load_study(PAPER_STUDY)
    found = conditions(study)
    assert [(c.schemes, c.rotation) for c in found] == [
        (("adaptive", "nfirst"), 0),
        (("adaptive", "nfirst"), 1),
        (("nfirst", "adaptive"), 0),
        (("nfirst", "adaptive"), 1),
    ]
    assert found[1].describe(study) == (  # part one mixes the schemes' clips; part two has a round per scheme
        "part 1: adaptive, nfirst shuffled together on paper-tl-br; part 2: adaptive then nfirst on paper-bl-tr"
    )


def test_concurrent_arrivals_are_balanced(make_client):
    client = make_client({"platform": '"prolific"', "assignment": '"balanced"'})
    errors = []

    def arrive(n: int) -> None:
        try:
            start(TestClient(client.app), f"?PROLIFIC_PID=p{n}&STUDY_ID=s&SESSION_ID=x{n}")
        except AssertionError as error:  # pragma: no cover - reported below
            errors.append(error)

    threads = [threading.Thread(target=arrive, args=(n,)) for n in range(24)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    people = stored(client, Participant)
    assert sorted(p.slot for p in people) == list(range(24))
    assert Counter(p.condition for p in people) == {0: 6, 1: 6, 2: 6, 3: 6}
    assert all(p.plan for p in people)


def test_one_person_opening_the_link_twice_at_once_gets_one_record(make_client):
    client = make_client({"platform": '"prolific"', "assignment": '"balanced"'})
    link = "/?PROLIFIC_PID=same&STUDY_ID=s&SESSION_ID=x"
    browsers = [TestClient(client.app) for _ in range(6)]
    tokens = [FormReader(b.get(link).text).hidden["csrf_token"] for b in browsers]
    codes = []

    def consent(browser, token):
        codes.append(browser.post("/consent", data={"csrf_token": token, "choice": "agree"}).status_code)

    threads = [threading.Thread(target=consent, args=pair) for pair in zip(browsers, tokens, strict=True)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert codes == [200] * 6
    (person,) = stored(client, Participant)
    assert person.slot == 0


def test_plan_is_seeded_and_randomises_order_and_answer_options(bundle_dir, tmp_path):
    from app.survey.bundle import load_bundle
    from tests.support.survey import study_text

    path = tmp_path / "study.toml"
    path.write_text(study_text())
    study, bundle = load_study(path), load_bundle(bundle_dir)
    condition = conditions(study)[0]
    plans = [build_plan(study, bundle, condition, random.Random(seed)) for seed in range(8)]
    assert build_plan(study, bundle, condition, random.Random(3)) == plans[3]
    assert len({tuple(s.clip for s in plan if isinstance(s, Pairwise)) for plan in plans}) > 1
    first_offered = {plan[1].robots[0].agent for plan in plans}
    assert len(first_offered) > 1
    for plan in plans:
        for screen in plan:
            if isinstance(screen, Ranking):
                assert screen.true_order == ["agenthighsecret", "agentmedsecret", "agentlowsecret"]
                assert len({r.label for r in screen.robots}) == 3
