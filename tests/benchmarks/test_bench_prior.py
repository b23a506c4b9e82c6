"""The prior benchmarks' halves, run side by side at one thread each: the second waits for the first's file and
writes one table of both, in order; a file of another run is refused."""

from __future__ import annotations

import argparse
import json
import threading
import time

import pytest

from benchmarks import bench_prior
from benchmarks.bench_prior import start_results, write_results

SAME = ("scan", "minutes")  # what two halves of one run share


def _half(tmp_path, name: str, join: str | None, rows: list[dict]) -> tuple[argparse.Namespace, dict]:
    a = argparse.Namespace(threads=1, join=None if join is None else tmp_path / join, out=tmp_path / name)
    results = start_results(a, {"scan": "s", "minutes": 3.0, "prior": list(rows), "scratch": []})
    return a, results


def test_the_second_half_waits_for_the_first_and_writes_both_in_order(tmp_path, monkeypatch):
    monkeypatch.setattr(bench_prior, "POLL_S", 0.02)
    first = _half(tmp_path, "first.json", None, [{"tune": "all", "lr": 3e-3}, {"tune": "all", "lr": 3e-4}])
    second = _half(tmp_path, "both.json", "first.json", [{"tune": "decoder", "lr": 1e-3}])
    waiting = threading.Thread(target=write_results, args=(*second, SAME, ("tune", "lr")))
    waiting.start()  # the first half is still running: nothing to join yet
    time.sleep(0.2)
    assert waiting.is_alive() and not (tmp_path / "both.json").exists()
    write_results(*first, SAME, ("tune", "lr"))
    waiting.join(5)
    both = json.loads((tmp_path / "both.json").read_text())
    assert [(r["tune"], r["lr"]) for r in both["prior"]] == [("all", 3e-4), ("all", 3e-3), ("decoder", 1e-3)]
    assert both["threads"] == 1 and both["minutes"] == 3.0


def test_a_file_of_another_run_is_not_joined(tmp_path):
    (tmp_path / "other.json").write_text(json.dumps({"scan": "s", "minutes": 1.0, "threads": 1, "prior": []}))
    with pytest.raises(SystemExit, match="not a half of this run"):
        write_results(*_half(tmp_path, "x.json", "other.json", []), SAME, ("lr",))
