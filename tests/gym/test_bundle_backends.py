"""A bundle's jobs on any backend: the tiny track's study (tests/gym/test_any_world.py) built in one process, in two
worker processes and as Ray tasks gives byte-identical bundles; its plan counts each step before any work; a job
that fails is named, and bad backend settings are refused with what to give instead."""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest

from search.bundle.build import build_bundle, prepare
from search.bundle.plan import plan_lines, plan_steps, step_seconds
from search.bundle.steps import Cache, Rate, Work, makespan
from search.cli import main
from search.solvers.runner import Backend, JobFailed
from tests.gym.test_any_world import ADAPTER, FAST, SLOW, STUDY


def bundle_files(out: Path) -> dict[str, bytes]:
    """Every file of a bundle but its cache (which keeps each search's wall time)."""
    return {
        str(path.relative_to(out)): path.read_bytes()
        for path in sorted(out.rglob("*"))
        if path.is_file() and path.relative_to(out).parts[0] != "cache"
    }


@pytest.fixture(scope="module")
def track(tmp_path_factory):
    """The track's study in a researcher's folder (its scenarios read from the working directory), and its bundle
    built in this process."""
    folder = tmp_path_factory.mktemp("track")
    (folder / "track.toml").write_text(f'adapter = "{ADAPTER}"\nseed = 3\n')
    (folder / "track-starts.toml").write_text(f'adapter = "{ADAPTER}"\n[distribution]\nseeds = [0, 100]\n')
    (folder / "study.toml").write_text(STUDY)
    before = os.getcwd()
    os.chdir(folder)
    try:
        log = []
        build_bundle("study.toml", "one", log=log.append, workers=1)
        yield folder, bundle_files(folder / "one"), log
    finally:
        os.chdir(before)


@pytest.fixture
def in_track(track, monkeypatch):
    monkeypatch.chdir(track[0])
    return track


def test_two_worker_processes_build_the_bundle_one_process_builds(in_track):
    folder, one, log = in_track
    two = []
    build_bundle("study.toml", "two", log=two.append, workers=2)
    assert bundle_files(folder / "two") == one
    finished = [line for line in two if line.startswith("search ")]
    assert len(finished) == 4 and finished[-1].endswith("[4/4]")  # progress: done of the step's, time left
    assert all("left]" in line for line in finished[:-1])
    assert "manifest.json" in one and any(name.endswith(".mp4") for name in one)


@pytest.mark.slow  # starts a local Ray instance
def test_ray_tasks_build_the_bundle_one_process_builds(in_track):
    folder, one, _ = in_track
    build_bundle("study.toml", "ray", log=lambda line: None, workers=2, backend="ray")
    assert bundle_files(folder / "ray") == one


def test_the_plan_counts_each_step_and_times_it_before_any_work(in_track, capsys):
    folder, _, _ = in_track
    assert main(["bundle", "study.toml", "--out", "planned", "--plan", "--jobs", "2"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("plan at --jobs 2, timed on this machine in ")
    assert lines[1].startswith("  evaluations: 2 agents x 4 episodes: about ")
    assert lines[2].startswith("  searches: 4 of 60 to 400 steps: about ")
    assert lines[3].startswith("  representativeness checks: 1 pair x (4 states + their scenarios) x 2 pushes: about")
    assert lines[4].startswith("  clips: 5 files to render: about ")  # the highlights clip is a pair of reels
    assert lines[5].startswith("  expected wall time: about ")
    assert not (folder / "planned").exists()
    cached = plan_lines(prepare("study.toml"), Cache(folder / "one" / "cache"), 1)  # a built bundle: nothing to time
    assert "evaluations: 2 agents x 4 episodes, 2 cached: about" in cached[1]
    assert "searches: 4 of 60 to 400 steps, 4 cached: about" in cached[2]
    assert "those whose summaries are unchanged reused" in cached[4]


def test_the_plan_sizes_each_job_and_times_it_at_its_groups_rate(in_track):
    folder, _, _ = in_track
    (folder / "doubled.toml").write_text(STUDY.replace("budget = 400", "budget = 800"))
    rates = {"": Rate(0.0, 5.0), "representative": Rate(0.01, 1.0), "nfirst": Rate(0.0, 2.0)}
    planned = {}
    for study in ("study.toml", "doubled.toml"):
        evaluations, searches, checks, _ = plan_steps(prepare(study), Cache(folder / "nothing"))
        assert evaluations.work == [Work(FAST, 4), Work(SLOW, 4)]  # each agent's episodes, at its own rate
        # 2 agents x (states + scenario) x (pushes + 1) x 50 steps
        assert checks.work == [Work("check", 2 * (4 + 1) * (2 + 1) * 50)]
        planned[study] = searches
    budgets = {study: {work.group: work.units for work in step.work} for study, step in planned.items()}
    assert budgets["study.toml"] == {"nfirst": 60, "representative": 400, "disagreements": 200, "highlights": 300}
    assert budgets["doubled.toml"]["representative"] == 800
    one, doubled = (step_seconds(planned[study], rates, 1) for study in ("study.toml", "doubled.toml"))
    assert one == 2.0 + (1.0 + 0.01 * 400) + 5.0 + 5.0  # a scheme without a rate of its own at the step's
    assert doubled - one == 0.01 * 400  # the representative search's 400 more steps at its rate
    assert step_seconds(planned["study.toml"], rates | {"": Rate(0.0, 5.0, warm_up=3.0)}, 2) == 3.0 + 5.0 + 5.0


def test_jobs_are_dealt_to_the_first_worker_free():
    assert makespan([4.0, 1.0, 1.0, 1.0], 2) == 4.0
    assert makespan([1.0, 1.0, 1.0, 1.0], 2) == 2.0
    assert makespan([2.0, 2.0], 8) == 2.0
    assert makespan([], 2) == 0.0


def fail(number: int) -> int:
    raise RuntimeError(f"no track {number}")


@pytest.mark.parametrize("workers", [1, 2])
def test_a_failed_job_is_named(workers):
    tasks = {("fast", "slow"): (fail, (3,))}
    with pytest.raises(JobFailed, match=r"^search nfirst track fast-slow failed: RuntimeError: no track 3$"):
        list(Backend("process", workers).run(tasks, lambda pair: f"search nfirst track {pair[0]}-{pair[1]}"))


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--jobs", "0"], "--jobs must be at least 1, got 0"),
        (["--ray-address", "10.0.0.5:6379"], "--ray-address needs --backend ray"),
        (["--backend", "ray", "--ray-address", "head node"], "bad Ray address 'head node': give HOST:PORT"),
    ],
)
def test_bad_backend_settings_are_refused_before_any_work(in_track, capsys, arguments, message):
    assert main(["bundle", "study.toml", "--out", "refused", *arguments]) == 2
    assert message in capsys.readouterr().err
    assert not (in_track[0] / "refused").exists()


def test_a_ray_address_where_no_cluster_answers_is_refused_at_once(in_track, capsys):
    """Ray itself retries such an address for minutes; the build says what is wrong before any work."""
    with socket.socket() as closed:  # a port that was free a moment ago: nothing listens on it
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]
    assert (
        main(["bundle", "study.toml", "--out", "refused", "--backend", "ray", "--ray-address", f"127.0.0.1:{port}"])
        == 2
    )
    err = capsys.readouterr().err
    assert f"no Ray cluster answers at 127.0.0.1:{port}" in err and "ray start --head" in err
    assert not (in_track[0] / "refused").exists()


def test_an_unknown_backend_is_refused(capsys):
    with pytest.raises(SystemExit):
        main(["bundle", "study.toml", "--out", "refused", "--backend", "slurm"])
    assert "invalid choice: 'slurm' (choose from 'process', 'ray')" in capsys.readouterr().err
    with pytest.raises(ValueError, match="unknown backend 'slurm': use 'process' or 'ray'"):
        Backend("slurm")
