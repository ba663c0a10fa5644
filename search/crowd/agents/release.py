"""Pick the shipped agents lo, med and hi from one training run and write their checkpoints and model cards.

    foil release RUN_DIR [--out DIR] [--episodes 500] [--every 2]

Every ``every``-th checkpoint of the run is evaluated on validation episodes (evaluation seed 1) at the clips'
horizon, 25 s, since that is what a study's viewers see. hi is the best snapshot (validation reward) that reaches
its goal in at least 95% of episodes with at most 3% timeouts; med and lo are earlier snapshots whose success-rate
and reward 95% intervals overlap neither each other's nor hi's, each the one whose reward is closest to the
paper's spacing of its agents (10.0 and 16.5 against 21.5 for the best). Their model cards report the test
evaluations that `foil eval NAME` prints (seed 0) at the training time limit and at 25 s, so the numbers shown
were not used to choose them. The shipped files keep only the weights and the training step.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

from search.core.release import VALIDATION_COLUMNS, ReleaseError, write_rows
from search.crowd.agents.dsrnn import DSRNN, DSRNNPolicy, NetworkConfig, read_checkpoint, save_checkpoint
from search.crowd.agents.evaluate import evaluate
from search.crowd.agents.train import checkpoints
from search.crowd.sim.world import WorldConfig

HORIZON_S = 25.0  # the clips' horizon: 100 steps of 0.25 s
HI_MIN_SUCCESS, HI_MAX_TIMEOUT = 0.95, 0.03
PAPER_REWARDS = {"lo": 10.0, "med": 16.5, "hi": 21.5}  # the paper's agents' mean episode rewards
VALIDATION_SEED, TEST_SEED = 1, 0
COLUMNS = (*VALIDATION_COLUMNS, "success_rate", "collision_rate", "timeout_rate")
REPRODUCE = "foil train --config search/crowd/agents/train.toml --out runs/agents\nfoil release runs/agents"


def policy_from(data: dict, name: str) -> DSRNNPolicy:
    net = DSRNN(NetworkConfig.from_dict(data["network"]))
    net.load_state_dict(data["model"])
    return DSRNNPolicy(net, name)


def validate_run(run_dir: Path, episodes: int, every: int, log=print) -> list[dict]:
    """Validation results at the 25 s horizon of every ``every``-th checkpoint, cached in RUN_DIR/validation.csv."""
    cache = run_dir / "validation.csv"
    done = {}
    if cache.exists():
        with cache.open() as f:
            rows = list(csv.DictReader(f))
        if rows and set(COLUMNS) <= set(rows[0]):
            done = {r["checkpoint"]: r for r in rows if int(r["episodes"]) == episodes}
    rows = []
    for path in checkpoints(run_dir)[every - 1 :: every]:
        if path.name not in done:
            data = read_checkpoint(path)
            result = evaluate(
                policy_from(data, path.stem), episodes, seed=VALIDATION_SEED, config=WorldConfig(time_limit=HORIZON_S)
            )
            done[path.name] = {
                "checkpoint": path.name,
                "env_steps": data["env_steps"],
                "episodes": episodes,
                "reward_mean": round(result["reward_mean"], 4),
                "reward_low": round(result["reward_ci95"][0], 4),
                "reward_high": round(result["reward_ci95"][1], 4),
                **{k: round(result[k], 4) for k in COLUMNS[len(VALIDATION_COLUMNS) :]},
            }
            log(
                f"{path.name}: {int(data['env_steps']):>9,} steps  reward {result['reward_mean']:6.2f}  "
                f"success {result['success_rate']:.3f}  timeout {result['timeout_rate']:.3f}"
            )
        rows.append(done[path.name])
    write_rows(cache, COLUMNS, rows)
    return rows


def success_interval(row: dict) -> tuple[float, float]:
    """Wilson 95% interval of a row's success rate."""
    n, p, z = int(row["episodes"]), float(row["success_rate"]), 1.96
    centre, half = p + z * z / (2 * n), z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (centre - half) / (1 + z * z / n), (centre + half) / (1 + z * z / n)


def separated(a: dict, b: dict) -> bool:
    """Whether two snapshots' success-rate and reward 95% intervals are disjoint."""
    (a_low, a_high), (b_low, b_high) = success_interval(a), success_interval(b)
    success = a_high < b_low or b_high < a_low
    reward = float(a["reward_high"]) < float(b["reward_low"]) or float(b["reward_high"]) < float(a["reward_low"])
    return success and reward


def choose(rows: list[dict]) -> dict[str, dict]:
    """hi, then med before it, then lo before that, as the module says."""
    qualified = [
        r for r in rows if float(r["success_rate"]) >= HI_MIN_SUCCESS and float(r["timeout_rate"]) <= HI_MAX_TIMEOUT
    ]
    if not qualified:
        best = max(rows, key=lambda r: float(r["success_rate"]), default=None)
        found = (
            "no checkpoints"
            if best is None
            else (
                f"the best snapshot, {best['checkpoint']}, succeeds in {float(best['success_rate']):.3f} with "
                f"{float(best['timeout_rate']):.3f} timeouts"
            )
        )
        raise ReleaseError(
            f"no snapshot reaches success >= {HI_MIN_SUCCESS} with timeouts <= {HI_MAX_TIMEOUT} "
            f"within {HORIZON_S:g} s ({found}); train the run longer (raise total_steps)"
        )
    chosen = {"hi": max(qualified, key=lambda r: float(r["reward_mean"]))}
    scale = float(chosen["hi"]["reward_mean"]) / PAPER_REWARDS["hi"]
    for name in ("med", "lo"):
        candidates = [
            r
            for r in rows
            if int(r["env_steps"]) < min(int(c["env_steps"]) for c in chosen.values())
            and all(separated(r, c) for c in chosen.values())
        ]
        if not candidates:
            raise ReleaseError(
                f"no snapshot before {min(c['checkpoint'] for c in chosen.values())} is clearly "
                f"worse than {sorted(chosen)} to be {name}; validate more checkpoints (--every 1)"
            )
        target = PAPER_REWARDS[name] * scale
        chosen[name] = min(candidates, key=lambda r: abs(float(r["reward_mean"]) - target))
    return {name: chosen[name] for name in PAPER_REWARDS}


def training_minutes(run_dir: Path, update: int) -> float:
    """Minutes of training the run had spent when it reached ``update`` (from its progress.csv)."""
    with (run_dir / "progress.csv").open() as f:
        return next(float(r["seconds"]) for r in csv.DictReader(f) if int(r["update"]) == update) / 60


def _rates(result: dict) -> str:
    low, high = result["reward_ci95"]
    nav = "n/a" if result["nav_time_mean"] is None else f"{result['nav_time_mean']:.2f} s"
    rates = " | ".join(f"{result[k]:.3f}" for k in ("success_rate", "collision_rate", "timeout_rate"))
    return f"| {result['time_limit']:g} s | {rates} | {result['reward_mean']:.2f} ({low:.2f} to {high:.2f}) | {nav} |"


def model_card(
    name: str, data: dict, results: list[dict], validation: dict, minutes: float, run: tuple[int, float]
) -> str:
    config = data["train_config"]
    network = ", ".join(f"{k} {v}" for k, v in data["network"].items())
    rows = "\n".join(_rates(result) for result in results)
    why = (
        f"the best validated snapshot that reaches its goal in at least {HI_MIN_SUCCESS:.0%} of episodes "
        f"with at most {HI_MAX_TIMEOUT:.0%} timeouts within {HORIZON_S:g} s"
        if name == "hi"
        else "an earlier snapshot whose success-rate and reward 95% intervals overlap those of neither other agent, "
        f"its reward closest to the paper's spacing ({PAPER_REWARDS[name]} against {PAPER_REWARDS['hi']} for "
        "the best)"
    )
    return f"""# Agent `{name}`

A DS-RNN crowd-navigation policy: a snapshot of one PPO run after **{data["env_steps"]:,} environment steps** \
({data["update"]} updates, {minutes:.0f} minutes of training on a shared 2-core CPU). It is {why}. Validation: \
{validation["episodes"]} episodes of at most {HORIZON_S:g} s, evaluation seed {VALIDATION_SEED}; it scored reward \
{float(validation["reward_mean"]):.2f} and success {float(validation["success_rate"]):.3f}.

**Observation.** The robot node carries the goal relative to the robot (offset, distance, unit direction) next \
to CrowdNav_DSRNN's absolute position and goal, a deliberate departure (see docs/agents.md).

**Network.** Same DS-RNN architecture as the paper's, narrower layers ({network}; the paper's: edge GRUs 256, \
node GRU 128, embeddings and attention 64, actor and critic 256), so that several seeds train on a 2-core CPU \
(docs/agents.md gives the measurements).

Training: PPO as CrowdNav_DSRNN trains it (normalised advantages, clipped value loss) with \
{config["num_envs"]} worlds x {config["num_steps"]} steps per update and learning rate {config["learning_rate"]} \
(the paper: 12 x 30 and 4e-5), 5 epochs, 2 recurrent minibatches, clip 0.2, GAE 0.95, gamma 0.99. The paper's \
world: 10 humans at 0.15 m/s, invisible robot, random training distribution, training time limit \
{config["world"]["time_limit"]:g} s. Seed {config["seed"]}.

## Test evaluation

`foil eval {name} --episodes {results[0]["episodes"]} --seed {TEST_SEED}` at the training time limit, and with \
`--time-limit {HORIZON_S:g}`, the horizon of the study's clips: test episodes, disjoint from training and \
validation episodes; deterministic action.

| time limit | success | collision | timeout | mean reward (95% CI) | mean navigation time (successes) |
|---:|---:|---:|---:|---|---:|
{rows}

## Reproduce

The whole run ({run[0]:,} steps) took {run[1]:.0f} minutes here; the second command \
validates the snapshots and writes all three agents and their cards.

```
{REPRODUCE}
```
"""


def release(run_dir: Path, out: Path, episodes: int, every: int, log=print) -> dict[str, dict]:
    """Choose lo, med and hi from ``run_dir`` and write their checkpoints and cards into ``out``."""
    rows = validate_run(run_dir, episodes, every, log)
    chosen = choose(rows)
    last = read_checkpoint(checkpoints(run_dir)[-1])
    run = last["env_steps"], training_minutes(run_dir, last["update"])
    summary = {}
    for name, row in chosen.items():
        data = read_checkpoint(run_dir / "checkpoints" / row["checkpoint"])
        policy = policy_from(data, name)
        results = [
            evaluate(policy, episodes, seed=TEST_SEED, config=WorldConfig(time_limit=limit)) | {"agent": name}
            for limit in (data["train_config"]["world"]["time_limit"], HORIZON_S)
        ]
        save_checkpoint(
            out / f"{name}.pt",
            policy.net,
            env_steps=data["env_steps"],
            update=data["update"],
            train_config=data["train_config"],
        )
        minutes = training_minutes(run_dir, data["update"])
        (out / f"{name}.md").write_text(model_card(name, data, results, row, minutes, run))
        summary[name] = {"checkpoint": row["checkpoint"], "test": results}
    return summary
