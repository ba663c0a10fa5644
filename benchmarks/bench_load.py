"""Survey server under load: `foil simulate`'s bots (app.analysis.bots.Bot, threads, through the lean keep-alive
client of tests/robustness/crowd.py) take the paper study at once against `foil serve` on loopback, clips included,
on the same machine as the server.

Six runs, each bounded in time and count (--runs picks some):
  ceiling  a minimal FastAPI endpoint returning a constant, served the way `foil serve` serves here (uvicorn, one
           process, httptools and uvloop, no access log), hammered by --concurrency clients for --seconds;
  burst    --concurrency bots with no pauses, new ones taking the place of those finished, for --seconds: page
           throughput (every non-video request: pages and form submissions) and its ratio to the ceiling.
           Ceiling and burst alternate for --rounds; in both the clients run in --processes processes (one
           interpreter lock each) pinned to all cores but the first, and the server is pinned to the first;
  paced    --participants bots arriving over --ramp seconds, each pausing --pause seconds before every form:
           completed sessions per minute, requests per second, p50/p95/p99 latency per page type, errors; and
           the server second by second (MONITOR: CPU, event-loop lag, thread pool, SQLite's write turn, the
           loop's wait for a CPU) with its slowest seconds. --bundle runs it on a built bundle's own study (the
           demo's), --stalled-output with the access log on and the server's output unread now and then;
  crash    --crash-participants paced bots; the server is killed with SIGKILL halfway through and restarted;
           the bots reopen their links and finish; then the database is audited;
  postgres the paced run again on a throwaway PostgreSQL server (tests/support/postgres.py; Debian's postgresql,
           durable settings: fsync and synchronous_commit on, as SQLite's synchronous=FULL), right after a paced
           run on SQLite in the same invocation: p95 and p99 per page type on both, and their ratio;
  cpu      server CPU per request, by kind: --cpu-sessions bots one at a time against `foil serve` (with its
           access log, as deployed) and 2,000 requests to the constant endpoint, reading the CPU time of all the
           server's threads from /proc/PID/task/*/schedstat around every request (Linux only; much less
           sensitive to the machine's load than latency is).

    .venv/bin/python benchmarks/bench_load.py [--participants 300] [--runs ceiling,burst] [--write]
    .venv/bin/python benchmarks/bench_load.py --runs paced,postgres  # PostgreSQL against SQLite
"""

from __future__ import annotations

import argparse
import glob
import multiprocessing
import os
import platform
import random
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from datetime import date
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.analysis.bots import Bot, ClipIndex, Observer  # noqa: E402
from app.survey.assignment import conditions  # noqa: E402
from app.survey.study import parse_study  # noqa: E402
from tests.support import postgres  # noqa: E402
from tests.support.analysis import write_bot_bundle  # noqa: E402
from tests.support.crowd import Crowd, LoopbackClient, audit, page_type  # noqa: E402
from tests.support.live_server import CROWD_FROM_ONE_ADDRESS, LiveServer, free_port  # noqa: E402
from tests.support.survey import study_text  # noqa: E402

CONSTANT_SERVER = """
import sys, uvicorn
from fastapi import FastAPI
app = FastAPI()
@app.get("/")
async def constant():
    return {"ok": True}
uvicorn.run(app, host="127.0.0.1", port=int(sys.argv[1]), proxy_headers=True, server_header=False,
            access_log=False)
"""
# As the constant server: a reverse proxy keeps the access log. The bots all come from 127.0.0.1.
SURVEY_SETTINGS = {"FOIL_ACCESS_LOG": "0", **CROWD_FROM_ONE_ADDRESS}
# The ceiling's and the burst's server on one core, their load generator on the others: the way a load test keeps
# its generator from taking the CPU of the system under test when both must share one machine.
CPUS = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
SERVER_CPUS, CLIENT_CPUS = (set(CPUS[:1]), set(CPUS[1:])) if len(CPUS) > 1 else (set(), set())
ORDER = ["landing", "consent", "study page", "answer", "clip"]
# The paced runs' server imports this as sitecustomize (through PYTHONPATH): each second it writes the server's CPU
# time, the event loop's largest lag (a 10 ms sleep that took longer), the thread pool's busiest moment (threads at
# work, tasks waiting for one), the slowest write transaction's wait for its turn and its time holding it (from
# the turn to the commit on disk), and how long the event loop's thread was ready to run but waited for a CPU (the
# machine's other work), so that a slow request can be traced to where it waited. A thread of its own writes the
# lines, so the watch never waits on the disk.
MONITOR = """
import asyncio, contextlib, os, queue, threading, time
import uvicorn.server
from app.store import database

_startup, _writing = uvicorn.server.Server.startup, database.Database.writing
_writes, _lock = {"turn": 0.0, "held": 0.0}, threading.Lock()


@contextlib.contextmanager
def _timed_writing(self):
    asked = time.monotonic()
    with _writing(self) as session:
        began = time.monotonic()
        yield session
    with _lock:
        _writes["turn"] = max(_writes["turn"], began - asked)
        _writes["held"] = max(_writes["held"], time.monotonic() - began)


def _write(path, lines):
    with open(path, "w", buffering=1) as out:
        while True:
            out.write(lines.get())


def _run_queue_s(path):
    with open(path) as stat:
        return int(stat.read().split()[1]) / 1e9


async def _watch(path):
    import anyio.to_thread

    limiter = anyio.to_thread.current_default_thread_limiter()
    lines = queue.SimpleQueue()
    threading.Thread(target=_write, args=(path, lines), daemon=True).start()
    schedstat = f"/proc/self/task/{threading.get_native_id()}/schedstat"
    second, lag, busy, waiting, ready = int(time.monotonic()), 0.0, 0, 0, _run_queue_s(schedstat)
    while True:
        before = time.monotonic()
        await asyncio.sleep(0.01)
        lag = max(lag, time.monotonic() - before - 0.01)
        stats = limiter.statistics()
        busy, waiting = max(busy, stats.borrowed_tokens), max(waiting, stats.tasks_waiting)
        if int(time.monotonic()) != second:
            with _lock:
                turn, held = _writes["turn"], _writes["held"]
                _writes.update(turn=0.0, held=0.0)
            was, ready = ready, _run_queue_s(schedstat)
            lines.put(
                f"{second} {time.process_time():.3f} {lag * 1000:.1f} {busy} {waiting} {turn * 1000:.1f} "
                f"{held * 1000:.1f} {(ready - was) * 1000:.1f}\\n"
            )
            second, lag, busy, waiting = int(time.monotonic()), 0.0, 0, 0


async def _startup_watched(self, sockets=None):
    asyncio.get_running_loop().create_task(_watch(os.environ["BENCH_MONITOR"]))
    return await _startup(self, sockets)


uvicorn.server.Server.startup = _startup_watched
database.Database.writing = _timed_writing
"""
RUNS = ["ceiling", "burst", "paced", "postgres", "crash", "cpu"]


def quantile(values: list[float], q: float) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, int(q * len(values)))] if values else float("nan")


def start_constant_server(workdir: Path) -> tuple[subprocess.Popen, int]:
    port = free_port()
    with (workdir / "constant.log").open("w") as log:
        server = subprocess.Popen(
            [sys.executable, "-c", CONSTANT_SERVER, str(port)], stdout=log, stderr=subprocess.STDOUT
        )
    probe = LoopbackClient(f"http://127.0.0.1:{port}")
    for _ in range(100):
        try:
            probe.get("/")
            break
        except OSError:
            time.sleep(0.1)
    probe.close()
    return server, port


def ceiling(concurrency: int, seconds: float, workdir: Path, processes: int) -> dict:
    """Requests per second of the constant endpoint, `concurrency` clients in a closed loop, and the server's CPU
    time per request."""
    server, port = start_constant_server(workdir)
    try:
        pin(server.pid, SERVER_CPUS)
        before = thread_cpu_s(server.pid)
        parts, wall = in_processes(_hammer, processes, concurrency, seconds, f"http://127.0.0.1:{port}")
        return {"per_s": sum(parts) / wall, "cpu_ms": (thread_cpu_s(server.pid) - before) / sum(parts) * 1000}
    finally:
        server.terminate()
        server.wait(timeout=30)


def _hammer(part: int, processes: int, concurrency: int, seconds: float, url: str) -> int:
    """This process's share of the ceiling's clients; the requests they made."""
    counts = [0] * len(range(part, concurrency, processes))
    stop = time.monotonic() + seconds

    def client(k: int) -> None:
        loopback = LoopbackClient(url)
        while time.monotonic() < stop:
            loopback.get("/")
            counts[k] += 1
        loopback.close()

    run_in_threads(client, len(counts))
    return sum(counts)


def in_processes(work, processes: int, *args) -> tuple[list, float]:
    """`work(part, processes, *args)` in `processes` fresh processes (one GIL each: the load generator's threads
    would queue on a single one), started together once all are ready; their results and the seconds until all
    had returned."""
    context = multiprocessing.get_context("spawn")
    ready, results = context.Barrier(processes + 1), context.Queue()
    workers = [
        context.Process(target=_work_in_process, args=(work, part, processes, args, ready, results))
        for part in range(processes)
    ]
    for worker in workers:
        worker.start()
    ready.wait(timeout=120)
    started = time.monotonic()
    parts = dict(results.get(timeout=3600) for _ in workers)
    wall = time.monotonic() - started
    for worker in workers:
        worker.join(timeout=60)
    return [parts[part] for part in range(processes)], wall


def _work_in_process(work, part: int, processes: int, args: tuple, ready, results) -> None:
    pin(os.getpid(), CLIENT_CPUS)
    ready.wait(timeout=120)
    results.put((part, work(part, processes, *args)))


def pin(pid: int, cpus: set[int]) -> None:
    """Keep every thread of process `pid` (and those it starts later) on `cpus`."""
    if cpus:
        for task in os.listdir(f"/proc/{pid}/task"):
            os.sched_setaffinity(int(task), cpus)


def run_in_threads(target, count: int) -> float:
    """Run ``target(k)`` for k in range(count), each in its own thread; the seconds until all have ended."""
    threads = [threading.Thread(target=target, args=(k,)) for k in range(count)]
    started = time.monotonic()
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return time.monotonic() - started


def serve(
    bundle: Path,
    study: Path,
    workdir: Path,
    database_url: str | None = None,
    monitor: bool = False,
    stalled_output: float = 0,
) -> LiveServer:
    """`foil serve` in `workdir`; with `monitor`, watched second by second (MONITOR, into workdir/monitor.txt); with
    `stalled_output`, its access log on and its output read as a terminal would, except that every other
    `stalled_output` seconds nothing reads it (a paused or scrolled-back terminal, a stalled SSH session)."""
    workdir.mkdir()
    env = dict(SURVEY_SETTINGS)
    if stalled_output:
        env["FOIL_ACCESS_LOG"] = "1"
        os.mkfifo(workdir / "server.log")
        threading.Thread(target=_stalling_reader, args=(workdir / "server.log", stalled_output), daemon=True).start()
    if monitor:
        (workdir / "site").mkdir()
        (workdir / "site" / "sitecustomize.py").write_text(MONITOR)
        env |= {"PYTHONPATH": f"{REPO}{os.pathsep}{workdir / 'site'}", "BENCH_MONITOR": str(workdir / "monitor.txt")}
    return LiveServer(
        bundle=bundle,
        study=study,
        workdir=workdir,
        env=env,
        database_url=database_url or f"sqlite:///{workdir / 'survey.sqlite3'}",
    )


def _stalling_reader(fifo: Path, stall_s: float) -> None:
    with open(fifo, "rb", buffering=0) as pipe:
        while True:
            if int(time.monotonic() / stall_s) % 2:
                time.sleep(0.05)
            elif not pipe.read(1 << 16):
                return


def burst(bundle: Path, study: Path, workdir: Path, concurrency: int, seconds: float, processes: int) -> dict:
    """Bots without pauses in `concurrency` lanes; each lane starts a new bot when its bot finishes."""
    with serve(bundle, study, workdir) as server:
        pin(server.process.pid, SERVER_CPUS)
        before = thread_cpu_s(server.process.pid)
        parts, wall = in_processes(_burst_lanes, processes, concurrency, seconds, server.url, str(bundle))
        cpu_s = thread_cpu_s(server.process.pid) - before
    pages = sum(part["pages"] for part in parts)
    return {
        "pages_per_s": pages / wall,
        "cpu_ms": cpu_s / pages * 1000,
        "sessions_per_min": sum(part["completed"] for part in parts) / wall * 60,
        "errors": sum(part["errors"] for part in parts),
        "requests": sum(part["requests"] for part in parts),
    }


def _burst_lanes(part: int, processes: int, concurrency: int, seconds: float, url: str, bundle: str) -> dict:
    """This process's share of the burst's lanes: what their bots did."""
    stop = time.monotonic() + seconds
    crowds: list[Crowd] = []
    clips = ClipIndex(bundle)
    lanes = range(part, concurrency, processes)

    def lane(k: int) -> None:
        n = 0
        while time.monotonic() < stop:
            crowd = Crowd(url, bundle, 1, seed=1000 * lanes[k] + n, clips=clips)
            crowds.append(crowd)
            crowd.run()
            n += 1

    run_in_threads(lane, len(lanes))
    log = [exchange for crowd in crowds for exchange in crowd.log]
    return {
        "pages": sum(exchange.kind != "clip" for exchange in log),
        "requests": len(log),
        "completed": sum(crowd.completed for crowd in crowds),
        "errors": sum(len(c.errors) for c in crowds),
    }


def paced(
    bundle: Path,
    study: Path,
    workdir: Path,
    participants: int,
    pause: float,
    ramp: float,
    database_url: str | None = None,
    stalled_output: float = 0,
) -> dict:
    with serve(bundle, study, workdir, database_url, monitor=True, stalled_output=stalled_output) as server:
        crowd = Crowd(server.url, str(bundle), participants, pause_s=pause, ramp_s=ramp, seed=1)
        wall = crowd.run()
    return {"crowd": crowd, "wall": wall, "seconds": seconds_table(workdir / "monitor.txt", crowd)}


def seconds_table(monitor: Path, crowd: Crowd) -> list[dict]:
    """The run second by second: the server's CPU (share of one core), the event loop's largest lag, the thread
    pool's most threads at work and most tasks waiting, the slowest write's wait for its turn and time holding it,
    and the requests that began in that second with their slowest and how many took over a second."""
    rows = [list(map(float, line.split())) for line in monitor.read_text().splitlines()]
    started: dict[int, list[float]] = defaultdict(list)
    for exchange in crowd.log:
        started[int(exchange.at - exchange.seconds)].append(exchange.seconds)
    table = []
    for (second, cpu, lag, busy, waiting, turn, held, ready), previous in zip(rows[1:], rows, strict=False):
        times = started.get(int(second), [])
        table.append(
            {
                "second": int(second),
                "cpu": (cpu - previous[1]) * 100,
                "lag_ms": lag,
                "busy": int(busy),
                "waiting": int(waiting),
                "turn_ms": turn,
                "held_ms": held,
                "ready_ms": ready,
                "requests": len(times),
                "slowest_s": max(times, default=0.0),
                "over_1s": sum(t > 1 for t in times),
            }
        )
    return [row for row in table if row["requests"]]


def crash(bundle: Path, study: Path, workdir: Path, participants: int, pause: float, ramp: float) -> dict:
    with serve(bundle, study, workdir) as server:
        crowd = Crowd(server.url, str(bundle), participants, pause_s=pause, ramp_s=ramp, seed=2, outage_s=120)
        runner = threading.Thread(target=crowd.run)
        runner.start()
        expected = participants * 15  # screens of the paper study
        while sum(len(p.client.acknowledged) for p in crowd.people) < expected // 2 and runner.is_alive():
            time.sleep(0.05)
        server.kill()
        killed_at = sum(len(p.client.acknowledged) for p in crowd.people)
        down = time.monotonic()
        server.start()
        restart_s = time.monotonic() - down
        runner.join()
    parsed = parse_study(study.read_text())
    result = audit(server.database_url, crowd, seed=parsed.study.seed, n_conditions=len(conditions(parsed)))
    return {"crowd": crowd, "audit": result, "killed_at": killed_at, "restart_s": restart_s}


def thread_cpu_s(pid: int) -> float:
    """CPU time of all the threads of process `pid` so far, in seconds."""
    total = 0
    for path in glob.glob(f"/proc/{pid}/task/*/schedstat"):
        try:
            with open(path) as stat:
                total += int(stat.read().split()[0])
        except OSError:  # a thread that ended
            pass
    return total / 1e9


class MeteredClient(LoopbackClient):
    """A bot's client that records the server's CPU time for every request, by kind."""

    def __init__(self, url: str, pid: int, cpu: dict[str, list[float]]):
        super().__init__(url)
        self.pid, self.cpu = pid, cpu

    def _exchange(self, method: str, target: str, body: str | None, headers: dict) -> tuple[int, str, str]:
        before = thread_cpu_s(self.pid)
        reply = super()._exchange(method, target, body, headers)
        time.sleep(0.001)  # what the server does after its reply (logging, closing the request) counts too
        self.cpu[page_type(method, target.split("?")[0])].append(thread_cpu_s(self.pid) - before)
        return reply


def cpu_per_request(bundle: Path, study: Path, workdir: Path, sessions: int) -> dict[str, tuple[int, float]]:
    """Server CPU (count, mean ms) per kind of request: bots one at a time, then the constant endpoint."""
    cpu: dict[str, list[float]] = defaultdict(list)
    clips = ClipIndex(bundle)
    workdir.mkdir()
    with LiveServer(
        bundle=bundle, study=study, database_url=f"sqlite:///{workdir / 'cpu.sqlite3'}", workdir=workdir
    ) as server:  # the access log on, as `foil serve` runs by default
        for k in range(sessions + 3):  # the first three warm the server up
            client = MeteredClient(server.url, server.process.pid, cpu if k >= 3 else defaultdict(list))
            Bot(client, clips, Observer(), random.Random(k), number=k, external_id=f"cpu-{k}").take_study()
            client.close()
    server, port = start_constant_server(workdir)
    try:
        client = MeteredClient(f"http://127.0.0.1:{port}", server.pid, defaultdict(list))
        for _ in range(2000):
            client.get("/")
        cpu["constant endpoint"] = client.cpu["landing"]
        client.close()
    finally:
        server.terminate()
        server.wait(timeout=30)
    return {kind: (len(v), sum(v) / len(v) * 1000) for kind, v in cpu.items()}


def by_kind_ms(crowd: Crowd) -> dict[str, list[float]]:
    by_kind: dict[str, list[float]] = defaultdict(list)
    for exchange in crowd.log:
        by_kind[exchange.kind].append(exchange.seconds * 1000)
    return by_kind


def database_table(crowds: dict[str, Crowd]) -> list[str]:
    """p95 and p99 per page type on each database, and PostgreSQL's p95 over SQLite's."""
    times = {name: by_kind_ms(crowd) for name, crowd in crowds.items()}
    rows = [
        "| request | SQLite p95 ms | SQLite p99 ms | PostgreSQL p95 ms | PostgreSQL p99 ms | p95 ratio |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for kind in ORDER:
        lite, pg = times["sqlite"].get(kind), times["postgresql"].get(kind)
        if lite and pg:
            rows.append(
                f"| {kind} | {quantile(lite, 0.95):.1f} | {quantile(lite, 0.99):.1f} | {quantile(pg, 0.95):.1f} | "
                f"{quantile(pg, 0.99):.1f} | {quantile(pg, 0.95) / quantile(lite, 0.95):.2f} |"
            )
    return rows


def seconds_summary(table: list[dict]) -> list[str]:
    """The server's seconds in brief, and the slowest seconds (those whose requests took longest) in full."""
    cpu, lag = [row["cpu"] for row in table], [row["lag_ms"] for row in table]
    slow = sorted(table, key=lambda row: -row["slowest_s"])[:8]
    start = table[0]["second"] if table else 0
    return [
        f"Second by second ({len(table)} s with requests): server CPU median {quantile(cpu, 0.5):.0f}% of a core, "
        f"max {max(cpu, default=0):.0f}%; event-loop lag median {quantile(lag, 0.5):.0f} ms, p95 "
        f"{quantile(lag, 0.95):.0f} ms, max {max(lag, default=0):.0f} ms ({sum(v > 100 for v in lag)} s over "
        f"100 ms); thread pool at most {max((r['busy'] for r in table), default=0)} threads at work, at most "
        f"{max((r['waiting'] for r in table), default=0)} tasks waiting for one "
        f"({sum(r['waiting'] > 0 for r in table)} s with any waiting); "
        f"slowest write's wait for its turn {max((r['turn_ms'] for r in table), default=0):.0f} ms, holding it "
        f"{max((r['held_ms'] for r in table), default=0):.0f} ms; the loop's thread waited for a CPU "
        f"{sum(r['ready_ms'] for r in table) / 1000:.1f} s in all, at most "
        f"{max((r['ready_ms'] for r in table), default=0):.0f} ms in a second; "
        f"{sum(r['over_1s'] for r in table)} requests over 1 s. The slowest seconds:",
        "",
        "| second | requests begun | over 1 s | slowest s | server CPU % | loop lag ms | threads at work | "
        "tasks waiting | write: turn ms | write: held ms | loop waited for a CPU ms |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        *(
            f"| {r['second'] - start} | {r['requests']} | {r['over_1s']} | {r['slowest_s']:.2f} | {r['cpu']:.0f} | "
            f"{r['lag_ms']:.0f} | {r['busy']} | {r['waiting']} | {r['turn_ms']:.0f} | {r['held_ms']:.0f} | "
            f"{r['ready_ms']:.0f} |"
            for r in sorted(slow, key=lambda row: row["second"])
        ),
    ]


def latency_table(crowd: Crowd) -> list[str]:
    by_kind: dict[str, list[float]] = defaultdict(list)
    for exchange in crowd.log:
        by_kind[exchange.kind].append(exchange.seconds * 1000)
    rows = ["| request | count | p50 ms | p95 ms | p99 ms | max ms |", "|---|---:|---:|---:|---:|---:|"]
    for kind in sorted(by_kind, key=lambda k: ORDER.index(k) if k in ORDER else len(ORDER)):
        v = by_kind[kind]
        rows.append(
            f"| {kind} | {len(v):,} | {quantile(v, 0.5):.1f} | {quantile(v, 0.95):.1f} | "
            f"{quantile(v, 0.99):.1f} | {max(v):.1f} |"
        )
    non_video = [e.seconds * 1000 for e in crowd.log if e.kind != "clip"]
    rows.append(
        f"| all non-video | {len(non_video):,} | {quantile(non_video, 0.5):.1f} | "
        f"{quantile(non_video, 0.95):.1f} | {quantile(non_video, 0.99):.1f} | {max(non_video):.1f} |"
    )
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", default=",".join(RUNS), help="which runs, comma-separated (default: all)")
    parser.add_argument("--participants", type=int, default=300)
    parser.add_argument("--pause", type=float, default=2.0, help="seconds before every form (default 2)")
    parser.add_argument("--ramp", type=float, default=10.0, help="arrivals spread over this many seconds")
    parser.add_argument("--concurrency", type=int, default=32, help="clients of the ceiling and burst runs")
    parser.add_argument("--seconds", type=float, default=20.0, help="length of the ceiling and burst runs")
    parser.add_argument("--rounds", type=int, default=3, help="ceiling-then-burst rounds (default 3)")
    parser.add_argument(
        "--processes",
        type=int,
        default=os.cpu_count(),
        help="load generator processes of the ceiling and burst runs, sharing the clients",
    )
    parser.add_argument("--crash-participants", type=int, default=100)
    parser.add_argument("--cpu-sessions", type=int, default=30, help="bots of the cpu run")
    parser.add_argument(
        "--sqlite-synchronous",
        choices=["full", "normal"],
        default="full",
        help="FOIL_SQLITE_SYNCHRONOUS of the survey server (default full, as deployed)",
    )
    parser.add_argument(
        "--bundle",
        type=Path,
        help="a built bundle with its study.toml (e.g. the demo's) instead of the paper study over 1-second clips",
    )
    parser.add_argument(
        "--stalled-output",
        type=float,
        default=0,
        metavar="S",
        help="the paced runs' server with its access log on, its output unread for S seconds every 2S seconds",
    )
    parser.add_argument("--write", action="store_true", help="append the results to BENCHMARKS.md")
    args = parser.parse_args()
    runs = set(args.runs.split(","))
    SURVEY_SETTINGS["FOIL_SQLITE_SYNCHRONOUS"] = args.sqlite_synchronous
    if not runs <= set(RUNS) or {"ceiling", "burst"} & runs and not {"ceiling", "burst"} <= runs:
        parser.error(f"--runs takes some of {', '.join(RUNS)}; ceiling and burst go together (their ratio)")

    lines = [
        f"{date.today()}, {os.cpu_count()} cores {platform.machine()}, SQLite synchronous="
        f"{args.sqlite_synchronous}; server and bots on the same machine (other work running; load averages from "
        "os.getloadavg() before each run)."
    ]
    ok = True
    with tempfile.TemporaryDirectory(prefix="foil-load-") as tmp:
        work = Path(tmp)
        (work / "clips").mkdir()
        (work / "bundle").mkdir()
        if args.bundle:
            bundle, study, studied = args.bundle, args.bundle / "study.toml", f"the study of {args.bundle}"
        else:
            bundle, study = write_bot_bundle(work / "clips", work / "bundle"), work / "study.toml"
            study.write_text(study_text(assignment='"balanced"'))  # MTurk ids, balanced assignment
            studied = "the paper study, MTurk ids, balanced assignment, 1-second clips"

        if "ceiling" in runs:
            lines += [
                "",
                f"Burst against ceiling, no pauses, {args.concurrency} bots or clients at a time, "
                f"{args.seconds:.0f} s each, alternating ({args.rounds} rounds; the machine's speed drifts, so "
                "each burst is compared with the ceiling measured just before it):",
                "",
                "| round | load average | constant endpoint req/s | its server CPU ms/req | burst non-video "
                "req/s | completed sessions/min | its server CPU ms/req | errors | ratio |",
                "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
            ]
            ratios = []
            for round_ in range(1, args.rounds + 1):
                load = os.getloadavg()[0]
                print(f"round {round_}: ceiling ...", flush=True)
                constant = ceiling(args.concurrency, args.seconds, work, args.processes)
                print(f"round {round_}: burst ...", flush=True)
                fast = burst(bundle, study, work / f"burst{round_}", args.concurrency, args.seconds, args.processes)
                ok &= not fast["errors"]
                ratios.append(fast["pages_per_s"] / constant["per_s"])
                lines.append(
                    f"| {round_} | {load:.1f} | {constant['per_s']:,.0f} | {constant['cpu_ms']:.3f} | "
                    f"{fast['pages_per_s']:,.0f} | {fast['sessions_per_min']:,.0f} | {fast['cpu_ms']:.3f} | "
                    f"{fast['errors']} | {ratios[-1]:.2f} |"
                )
            lines += [
                "",
                f"Ratio, median of the rounds: **{statistics.median(ratios):.2f}** (range "
                f"{min(ratios):.2f}-{max(ratios):.2f}).",
            ]
        if "paced" in runs:
            load = os.getloadavg()[0]
            print("paced ...", flush=True)
            slow = paced(
                bundle, study, work / "paced", args.participants, args.pause, args.ramp, None, args.stalled_output
            )
            crowd, wall = slow["crowd"], slow["wall"]
            sqlite_crowd = crowd
            output = (
                f"access log on, its output unread {args.stalled_output:.0f} s of every {2 * args.stalled_output:.0f}; "
                if args.stalled_output
                else ""
            )
            non_video = [e.seconds * 1000 for e in crowd.log if e.kind != "clip"]
            bad_status = sum(e.status >= 400 for e in crowd.log)
            ok &= crowd.completed == args.participants and not crowd.errors and not bad_status
            lines += [
                "",
                f"Paced: {args.participants} bots arriving over {args.ramp:.0f} s, {args.pause:.0f} s "
                f"before every form ({studied}: {len(crowd.log) / args.participants:.0f} requests per "
                f"participant; {output}load average {load:.1f} before): {crowd.completed} of {args.participants} "
                f"completed in {wall:.0f} s ({crowd.completed / wall * 60:.0f} completed sessions/min, "
                f"{len(non_video) / wall:.0f} non-video requests/s), "
                f"{len(crowd.errors)} bot errors, {bad_status} HTTP errors; p95 of non-video requests "
                f"{quantile(non_video, 0.95):.0f} ms.",
                "",
                *latency_table(crowd),
                "",
                *seconds_summary(slow["seconds"]),
            ]
            for error in crowd.errors[:10]:
                print("error:", error)
        if "postgres" in runs:
            if "paced" not in runs:
                parser.error("--runs postgres compares with the paced run on SQLite: add paced")
            bin_dir = postgres.binaries()
            if bin_dir is None:
                parser.error("no PostgreSQL binaries (initdb, pg_ctl): apt-get install postgresql")
            server = postgres.ThrowawayServer(bin_dir)
            try:
                server.start(durable=True)
                load = os.getloadavg()[0]
                print("paced on PostgreSQL ...", flush=True)
                slow = paced(
                    bundle,
                    study,
                    work / "paced-postgres",
                    args.participants,
                    args.pause,
                    args.ramp,
                    database_url=server.url,
                    stalled_output=args.stalled_output,
                )
            finally:
                server.stop()
            crowd, wall = slow["crowd"], slow["wall"]
            bad_status = sum(e.status >= 400 for e in crowd.log)
            ok &= crowd.completed == args.participants and not crowd.errors and not bad_status
            lines += [
                "",
                f"Paced on PostgreSQL (the same bots right after the paced run on SQLite; PostgreSQL "
                f"{bin_dir.parent.name} on loopback, fsync and synchronous_commit on; load average {load:.1f} "
                f"before): {crowd.completed} of {args.participants} completed in {wall:.0f} s, "
                f"{len(crowd.errors)} bot errors, {bad_status} HTTP errors.",
                "",
                *database_table({"sqlite": sqlite_crowd, "postgresql": crowd}),
                "",
                *seconds_summary(slow["seconds"]),
            ]
        if "crash" in runs:
            print("crash ...", flush=True)
            killed = crash(bundle, study, work / "crash", args.crash_participants, args.pause, args.ramp)
            result = killed["audit"]
            ok &= result.ok and killed["crowd"].completed == args.crash_participants
            lines += [
                "",
                f"Crash: {args.crash_participants} paced bots; SIGKILL after {killed['killed_at']} "
                f"acknowledged answers, restarted in {killed['restart_s']:.1f} s; {killed['crowd'].completed} "
                f"of {args.crash_participants} completed ({sum(p.interruptions for p in killed['crowd'].people)} "
                f"bot interruptions, {len(killed['crowd'].errors)} errors); {result.acknowledged} acknowledged "
                f"answers, {len(result.missing)} missing from the database; {result.participants} participants, "
                f"{len(result.duplicated)} duplicated; per condition {result.conditions} "
                f"({'balanced' if not result.balance_problems else '; '.join(result.balance_problems)}).",
            ]
            for error in killed["crowd"].errors[:10]:
                print("error:", error)
        if "cpu" in runs:
            load = os.getloadavg()[0]
            print("cpu ...", flush=True)
            cpu = cpu_per_request(bundle, study, work / "cpu", args.cpu_sessions)
            lines += [
                "",
                f"Server CPU per request ({args.cpu_sessions} bots one at a time, load average {load:.1f} before):",
                "",
                "| request | count | CPU ms |",
                "|---|---:|---:|",
            ]
            lines += [
                f"| {kind} | {n:,} | {ms:.2f} |"
                for kind, (n, ms) in sorted(
                    cpu.items(), key=lambda item: ORDER.index(item[0]) if item[0] in ORDER else len(ORDER)
                )
            ]

    text = "\n".join(lines)
    print(text)
    if args.write:
        path = REPO / "BENCHMARKS.md"
        current = path.read_text()
        heading = "## Survey server under load (`bench_load.py`)"
        intro = f"{heading}\n\n{__doc__.split(chr(10) + chr(10))[1].strip()}\n\n" if heading not in current else ""
        path.write_text(current.rstrip("\n") + "\n\n" + intro + text + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
