"""Pick highway-lo, highway-med and highway-hi from one highway training run; write their files and model cards.

    foil release runs/highway [--out DIR] [--episodes 500] [--every 2] [--jobs 3]

Every ``every``-th checkpoint (and the last) is validated on ``VALIDATION_EPISODES`` episodes of evaluation seed
1. hi is the snapshot with the best validation reward; lo is the earliest validated snapshot, and med the one
between them whose reward is closest to the middle of theirs, each clearly apart from the others in validation
(collision-rate and reward 95% intervals disjoint). The three are then tested on ``episodes`` episodes of seed 0,
which must keep them apart; the model cards report those test numbers, which played no part in the choice.
"""

from __future__ import annotations

import csv
import json
import re
import shutil
from pathlib import Path

from search.core.release import VALIDATION_COLUMNS, ReleaseError, write_rows
from search.gym.agents import GymAgent, load_sb3
from search.highway.adapter import AGENTS_DIR, HighwayAdapter
from search.highway.evaluate import evaluate

VALIDATION_EPISODES = 100  # DQN's snapshots differ by less than 30 episodes can tell
VALIDATION_SEED, TEST_SEED = 1, 0
COLUMNS = (*VALIDATION_COLUMNS, "collision_rate", "collision_low", "collision_high")
REPRODUCE = (
    "foil train --config search/highway/train.toml --out runs/highway\n"
    "foil release runs/highway --out search/highway/agents --every 1 --jobs 3"
)


def is_highway_run(run_dir: Path) -> bool:
    config = Path(run_dir) / "config.json"
    return config.is_file() and json.loads(config.read_text()).get("domain") == "highway"


def checkpoints(run_dir: Path) -> list[Path]:
    """The run's checkpoints, by environment steps."""
    found = [
        (int(m.group(1)), p)
        for p in (run_dir / "checkpoints").glob("model_*_steps.zip")
        if (m := re.fullmatch(r"model_(\d+)_steps", p.stem))
    ]
    return [p for _, p in sorted(found)]


def _row(path: Path, result: dict) -> dict:
    return {
        "checkpoint": path.name,
        "env_steps": int(path.stem.split("_")[1]),
        "episodes": result["episodes"],
        "reward_mean": round(result["reward_mean"], 4),
        "reward_low": round(result["reward_ci95"][0], 4),
        "reward_high": round(result["reward_ci95"][1], 4),
        "collision_rate": round(result["collision_rate"], 4),
        "collision_low": round(result["collision_ci95"][0], 4),
        "collision_high": round(result["collision_ci95"][1], 4),
    }


def validate_run(run_dir: Path, every: int, log=print) -> list[dict]:
    """Validation rows of every ``every``-th checkpoint and the last, cached in RUN_DIR/validation.csv."""
    cache = run_dir / "validation.csv"
    done = {}
    if cache.exists():
        with cache.open() as f:
            done = {r["checkpoint"]: r for r in csv.DictReader(f) if int(r["episodes"]) == VALIDATION_EPISODES}
    paths = checkpoints(run_dir)
    if not paths:
        raise ReleaseError(f"{run_dir}: no checkpoints; train first: foil train --config search/highway/train.toml")
    chosen = list(dict.fromkeys(paths[::every] + paths[-1:]))
    adapter, rows = HighwayAdapter(), []
    for path in chosen:
        if path.name not in done:
            result = evaluate(
                GymAgent(path.stem, str(path), load_sb3(path)), VALIDATION_EPISODES, VALIDATION_SEED, adapter
            )
            done[path.name] = _row(path, result)
            log(f"{path.name}: reward {result['reward_mean']:6.2f}  collisions {result['collision_rate']:.3f}")
        rows.append(done[path.name])
    write_rows(cache, COLUMNS, rows)
    return rows


def apart(a: dict, b: dict) -> bool:
    """Whether two rows' collision-rate and reward 95% intervals are disjoint."""

    def disjoint(low: str, high: str) -> bool:
        return float(a[high]) < float(b[low]) or float(b[high]) < float(a[low])

    return disjoint("collision_low", "collision_high") and disjoint("reward_low", "reward_high")


def choose(rows: list[dict]) -> dict[str, dict]:
    hi = max(rows, key=lambda r: float(r["reward_mean"]))
    lo = next((r for r in rows if apart(r, hi)), None)
    if lo is None:
        raise ReleaseError("no validated snapshot is clearly worse than the best; validate more (--every 1)")
    middle = (float(lo["reward_mean"]) + float(hi["reward_mean"])) / 2
    between = [
        r
        for r in rows
        if int(lo["env_steps"]) < int(r["env_steps"]) < int(hi["env_steps"]) and apart(r, lo) and apart(r, hi)
    ]
    if not between:
        raise ReleaseError(
            f"no snapshot between {lo['checkpoint']} and {hi['checkpoint']} is clearly apart from "
            "both; validate every checkpoint (--every 1) or save checkpoints more often"
        )
    med = min(between, key=lambda r: abs(float(r["reward_mean"]) - middle))
    return {"lo": lo, "med": med, "hi": hi}


def _minutes(run_dir: Path, steps: int) -> float:
    with (run_dir / "progress.csv").open() as f:
        rows = [r for r in csv.DictReader(f) if int(r["time/total_timesteps"]) <= max(steps, 1)]
    return float(rows[-1]["time/time_elapsed"]) / 60 if rows else 0.0


def model_card(name: str, row: dict, test: dict, config: dict, minutes: float) -> str:
    why = {
        "hi": "the validated snapshot with the best mean reward",
        "lo": "the earliest validated snapshot clearly worse than hi",
        "med": "the snapshot between lo and hi whose validation reward is closest to the middle of theirs, "
        "clearly apart from both",
    }[name]
    low, high = test["collision_ci95"]
    r_low, r_high = test["reward_ci95"]
    speed = test["score"]
    s_low, s_high = speed["ci95"]
    return f"""# Agent `highway-{name}`

A highway driving policy (Stable-Baselines3 DQN, MLP {config["hidden"]}x{config["hidden"]}) for highway-env's \
`highway-fast-v0` with its discrete meta-actions (change lane, keep going, faster, slower between 72, 90 and 108 \
km/h; a car cannot stop or reverse: Foil's world, search/highway/env.py): the snapshot of one training run after \
**{int(row["env_steps"]):,} environment steps** ({_took(minutes)} of training on a shared 2-core CPU). It is \
{why}. Validation: {row["episodes"]} episodes of evaluation seed {VALIDATION_SEED}; reward \
{float(row["reward_mean"]):.2f}, collision rate {float(row["collision_rate"]):.3f}.

**How it drives** in the test episodes below: {_drives(test)} Its mean speed is {speed["mean"]:.1f} km/h \
({s_low:.1f} to {s_high:.1f}; the other cars start at 83 to 90 km/h); it changes lanes \
{test["lane_changes_mean"]:.1f} times a drive; it crashes in {test["collision_rate"]:.0%} of its drives.

Training: DQN as highway-env's own example trains it: {config["total_steps"]:,} environment steps, replay buffer \
{config["buffer_size"]:,}, learning from step {config["learning_starts"]}, batch {config["batch_size"]}, learning \
rate {config["learning_rate"]}, gamma {config["gamma"]}, target network updated every \
{config["target_update_interval"]} steps, exploration decaying over the first {config["exploration_fraction"]:.0%} \
of training, seed {config["seed"]}; highway-env's own reward (speed between 72 and 108 km/h, right lane, no \
collision; 0 to 1 per second).

## Test evaluation

`foil eval highway-{name} --episodes {test["episodes"]} --seed {TEST_SEED}`: episodes disjoint from training and \
validation; deterministic action; an episode ends with a crash, leaving the road, or after 30 s.

| episodes | collision rate (95% CI) | mean reward (95% CI) | mean length |
|---:|---|---|---:|
| {test["episodes"]} | {test["collision_rate"]:.3f} ({low:.3f} to {high:.3f}) | {test["reward_mean"]:.2f} \
({r_low:.2f} to {r_high:.2f}) | {test["length_mean"]:.1f} s |

## Reproduce

```
{REPRODUCE}
```
"""


def _took(minutes: float) -> str:
    return f"{minutes:.0f} minutes" if minutes >= 2 else f"{60 * minutes:.0f} seconds"


def _drives(test: dict) -> str:
    """One sentence a driver would say of the test drives."""
    crashes, speed = test["collision_rate"], test["score"]["mean"]
    safety = "rarely crashes" if crashes < 0.1 else "crashes often" if crashes > 0.3 else "crashes now and then"
    pace = "keeps up with the traffic" if speed >= 80 else "drives slower than most of the traffic"
    return f"it {safety} and {pace}."


def _test(name: str, path: Path, episodes: int) -> dict:
    return evaluate(GymAgent(f"highway-{name}", str(path), load_sb3(path)), episodes, TEST_SEED, HighwayAdapter())


def release(run_dir: Path, out: Path | None, episodes: int, every: int, log=print, jobs: int = 1) -> dict[str, dict]:
    """Choose lo, med and hi from ``run_dir`` and write ``out``/{lo,med,hi}.zip with their model cards; the three
    test evaluations run in ``jobs`` processes."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    run_dir, out = Path(run_dir), Path(out or AGENTS_DIR)
    chosen = choose(validate_run(run_dir, every, log))
    paths = {name: run_dir / "checkpoints" / row["checkpoint"] for name, row in chosen.items()}
    if jobs > 1:
        with ProcessPoolExecutor(min(jobs, 3), mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = {name: pool.submit(_test, name, path, episodes) for name, path in paths.items()}
            tests = {name: future.result() for name, future in futures.items()}
    else:
        tests = {name: _test(name, path, episodes) for name, path in paths.items()}
    for name, test in tests.items():
        log(
            f"highway-{name} = {chosen[name]['checkpoint']}: test reward {test['reward_mean']:.2f}, collisions "
            f"{test['collision_rate']:.3f}"
        )
    rows = {name: _row(Path(chosen[name]["checkpoint"]), tests[name]) for name in chosen}
    clashes = [f"{a}/{b}" for a, b in (("lo", "med"), ("med", "hi"), ("lo", "hi")) if not apart(rows[a], rows[b])]
    if clashes:
        raise ReleaseError(
            f"on {episodes} test episodes the intervals of {clashes} overlap; validate every "
            "checkpoint (--every 1) or train longer"
        )
    config = json.loads((run_dir / "config.json").read_text())
    out.mkdir(parents=True, exist_ok=True)
    for name, row in chosen.items():
        shutil.copyfile(run_dir / "checkpoints" / row["checkpoint"], out / f"{name}.zip")
        minutes = _minutes(run_dir, int(row["env_steps"]))
        (out / f"{name}.md").write_text(model_card(name, row, tests[name], config, minutes))
    return {name: {"checkpoint": chosen[name]["checkpoint"], "test": tests[name]} for name in chosen}
