"""Pick the shipped agents lo, med and hi from one training run and write their checkpoints and model cards.

    python -m search.release_agents RUN_DIR [--out search/agents] [--episodes 500] [--every 5]

Every ``every``-th checkpoint of the run is evaluated on validation episodes (evaluation seed 1); hi is the
checkpoint whose validation reward is closest to the paper's 21.5, med the one closest to 16.5 among earlier
checkpoints, lo the one closest to 10.0 before med. Their model cards report the test evaluation that
`foil eval NAME` prints (seed 0), so the numbers shown were not used to choose them. The shipped files keep
only the weights and the training step.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

from search.dsrnn import DSRNN, DSRNNPolicy, NetworkConfig, read_checkpoint, save_checkpoint
from search.evaluate import evaluate
from search.train import checkpoints

TARGETS = {"lo": 10.0, "med": 16.5, "hi": 21.5}  # the paper's mean episode rewards
VALIDATION_SEED, TEST_SEED = 1, 0
REPRODUCE = ("foil train --config search/agents/train.toml --out runs/agents\n"
             "python -m search.release_agents runs/agents")


def policy_from(data: dict, name: str) -> DSRNNPolicy:
    net = DSRNN(NetworkConfig.from_dict(data["network"]))
    net.load_state_dict(data["model"])
    return DSRNNPolicy(net, name)


def validate_run(run_dir: Path, episodes: int, every: int) -> list[dict]:
    """Validation results of every ``every``-th checkpoint, cached in RUN_DIR/validation.csv."""
    cache = run_dir / "validation.csv"
    done = {}
    if cache.exists():
        with cache.open() as f:
            done = {r["checkpoint"]: r for r in csv.DictReader(f) if int(r["episodes"]) == episodes}
    rows = []
    for path in checkpoints(run_dir)[every - 1::every]:
        if path.name not in done:
            data = read_checkpoint(path)
            result = evaluate(policy_from(data, path.stem), episodes, seed=VALIDATION_SEED)
            done[path.name] = {"checkpoint": path.name, "env_steps": data["env_steps"], "episodes": episodes,
                               "reward_mean": round(result["reward_mean"], 4),
                               "success_rate": round(result["success_rate"], 4)}
            print(f"{path.name}: {done[path.name]['env_steps']:>9,} steps  reward {result['reward_mean']:6.2f}  "
                  f"success {result['success_rate']:.3f}", flush=True)
        rows.append(done[path.name])
    with cache.open("w", newline="") as f:
        writer = csv.DictWriter(f, ["checkpoint", "env_steps", "episodes", "reward_mean", "success_rate"])
        writer.writeheader()
        writer.writerows(rows)
    return rows


def choose(rows: list[dict]) -> dict[str, dict]:
    """hi, then med before it, then lo before that: each the snapshot whose validation reward is closest to its
    target, so the three come from ever later training in the order of their rewards."""
    chosen, candidates = {}, rows
    for name in reversed(TARGETS):
        if not candidates:
            raise SystemExit(f"not enough validated checkpoints before {chosen} to choose {name}")
        chosen[name] = min(candidates, key=lambda r: abs(float(r["reward_mean"]) - TARGETS[name]))
        candidates = [r for r in candidates if int(r["env_steps"]) < int(chosen[name]["env_steps"])]
    return {name: chosen[name] for name in TARGETS}


def training_minutes(run_dir: Path, update: int) -> float:
    """Minutes of training the run had spent when it reached ``update`` (from its progress.csv)."""
    with (run_dir / "progress.csv").open() as f:
        return next(float(r["seconds"]) for r in csv.DictReader(f) if int(r["update"]) == update) / 60


def model_card(name: str, data: dict, result: dict, validation: dict, minutes: float,
               run: tuple[int, float]) -> str:
    config = data["train_config"]
    low, high = result["reward_ci95"]
    network = ", ".join(f"{k} {v}" for k, v in data["network"].items())
    rates = " | ".join(f"{result[k]:.3f}" for k in ("success_rate", "collision_rate", "timeout_rate"))
    return f"""# Agent `{name}`

A DS-RNN crowd-navigation policy: a snapshot of one PPO run after **{data['env_steps']:,} environment steps** \
({data['update']} updates, {minutes:.0f} minutes of training on a shared 2-core CPU). It is the snapshot whose \
validation reward was closest to the paper's {TARGETS[name]} (validation: 500 episodes, evaluation seed \
{VALIDATION_SEED}, every fifth checkpoint; it scored {float(validation['reward_mean']):.2f}).

**Smaller than the paper's network.** Same DS-RNN architecture, narrower layers ({network}; the paper's: edge \
GRUs 256, node GRU 128, embeddings and attention 64, actor and critic 256), so that the run trains on a CPU.

Training: PPO with {config['num_envs']} worlds x {config['num_steps']} steps per update and learning rate \
{config['learning_rate']} (the paper: 12 x 30 and 4e-5); other settings as in DESIGN.md. The paper's world: 10 \
humans at 0.15 m/s, invisible robot, random training distribution, time limit 50 s. Seed {config['seed']}.

## Test evaluation

`foil eval {name} --episodes {result['episodes']} --seed {TEST_SEED}`: test episodes, disjoint from training and \
validation episodes; deterministic action.

| success | collision | timeout | mean reward (95% CI) | mean navigation time (successes) |
|---:|---:|---:|---|---:|
| {rates} | {result['reward_mean']:.2f} ({low:.2f} to {high:.2f}) | {result['nav_time_mean']:.2f} s |

## Reproduce

The whole run ({run[0]:,} steps) took {run[1]:.0f} minutes here; the second command \
validates the snapshots and writes all three agents and their cards.

```
{REPRODUCE}
```
"""


def main() -> None:
    parser = argparse.ArgumentParser(description="pick and ship lo, med and hi from a training run")
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "agents")
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--every", type=int, default=5, help="validate every N-th checkpoint")
    parser.add_argument("--validate-only", action="store_true", help="print the validation curve, ship nothing")
    args = parser.parse_args()
    rows = validate_run(args.run_dir, args.episodes, args.every)
    if args.validate_only:
        return
    if not rows:
        raise SystemExit(f"no checkpoints in {args.run_dir / 'checkpoints'}")
    summary = {}
    last = read_checkpoint(checkpoints(args.run_dir)[-1])
    run = last["env_steps"], training_minutes(args.run_dir, last["update"])
    for name, row in choose(rows).items():
        data = read_checkpoint(args.run_dir / "checkpoints" / row["checkpoint"])
        policy = policy_from(data, name)
        result = evaluate(policy, args.episodes, seed=TEST_SEED) | {"agent": name}
        save_checkpoint(args.out / f"{name}.pt", policy.net, env_steps=data["env_steps"], update=data["update"],
                        train_config=data["train_config"])
        minutes = training_minutes(args.run_dir, data["update"])
        (args.out / f"{name}.md").write_text(model_card(name, data, result, row, minutes, run))
        summary[name] = {"checkpoint": row["checkpoint"], **result}
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
