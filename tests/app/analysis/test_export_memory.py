"""The export streams: six times the participants take about the same peak memory (benchmarks/bench_export.py
measures 10,000)."""

from __future__ import annotations

import importlib.util
import tracemalloc
from pathlib import Path

import pytest

from app.analysis.export_csv import export_study
from app.store.database import Database, migrate

BENCH = Path(__file__).resolve().parents[3] / "benchmarks" / "bench_export.py"


def load_bench():
    spec = importlib.util.spec_from_file_location("bench_export", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def peak_bytes(tmp_path: Path, n: int) -> tuple[int, int]:
    bench = load_bench()
    url = f"sqlite:///{tmp_path / f'big{n}.sqlite3'}"
    migrate(url)
    bench.fill(url, n)
    db = Database(url)
    study = bench.load_study(bench.STUDY)
    tracemalloc.start()
    result = export_study(db, study, tmp_path / f"out{n}", batch=50)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    db.dispose()
    return peak, result.answers


@pytest.mark.slow
def test_export_memory_does_not_grow_with_participants(tmp_path):
    small, small_rows = peak_bytes(tmp_path, 100)
    large, large_rows = peak_bytes(tmp_path, 600)
    assert large_rows == 6 * small_rows
    assert large < 1.5 * small, (small, large)
