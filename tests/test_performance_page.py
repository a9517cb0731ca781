"""docs/performance.md is what `python -m bench perf_page` makes from the bench JSON it names
(so a hand edit fails here), and the page's verdicts follow the whole run-to-run spread."""
from __future__ import annotations

import copy
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from bench._perf_page import AIMS, AT_THRESHOLD, HELD, NOT_JUDGED, NOT_MET, judge, render

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "performance.md"


def _named_json(page: str) -> str:
    found = re.search(r"python -m bench perf_page (\S+) --out docs/performance\.md", page)
    assert found, "the page does not name the JSON it was made from"
    return found.group(1)


def test_the_page_is_what_the_generator_makes_from_its_json():
    page = PAGE.read_text(encoding="utf-8")
    name = _named_json(page)
    bench = json.loads((REPO / name).read_text(encoding="utf-8"))
    assert page == render(bench, name)


def test_a_hand_edit_is_caught():
    """The comparison above fails on a page whose verdict was changed by hand."""
    page = PAGE.read_text(encoding="utf-8")
    name = _named_json(page)
    bench = json.loads((REPO / name).read_text(encoding="utf-8"))
    edited = re.sub(r"\*\*[^*]+\*\* \|$", f"**{HELD}** |", page, count=1, flags=re.M)
    edited = edited if edited != page else page.replace("median", "typical", 1)
    assert edited != render(bench, name)


def test_the_command_writes_the_page(tmp_path):
    name = _named_json(PAGE.read_text(encoding="utf-8"))
    out = tmp_path / "page.md"
    subprocess.run([sys.executable, "-m", "bench", "perf_page", name, "--out", str(out)],
                   cwd=REPO, check=True, timeout=60)
    assert out.read_text(encoding="utf-8") == PAGE.read_text(encoding="utf-8")


def _bench(ratio_range, rate_range, pty_range, startup):
    """A bench JSON with the four aims' figures (hand-made; medians mid-range)."""
    return {"_run": {"date_utc": "D", "command": "python -m bench session", "machine": "M",
                     "system": "S", "python": "3"},
            "session": {
                "lockstep": {"stub, stub+log, plant_only interleaved": {
                    "stub+log_vs_plant_only": sum(ratio_range) / 2,
                    "per_round_ratio_range": ratio_range,
                    "stub+log": {"periods_per_s": sum(rate_range) / 2,
                                 "batch_periods_per_s_range": rate_range}}},
                "stub_pty_vs_bare_pty": {"stub_pty_vs_bare": sum(pty_range) / 2,
                                         "per_batch_ratio_range": pty_range},
                "hil_run_startup": {"median_s": sum(startup) / 2, "min_s": startup[0],
                                    "max_s": startup[1]}}}


@pytest.mark.parametrize("figures, verdicts", [
    # every spread clears its aim
    (([1.5, 1.9], [120_000, 150_000], [0.85, 0.95], [0.2, 0.29]), [HELD] * 4),
    # the aims lie inside the spreads: a median that clears is not enough
    (([1.9, 2.1], [90_000, 110_000], [0.75, 0.85], [0.25, 0.35]), [AT_THRESHOLD] * 4),
    # every spread misses
    (([2.1, 2.5], [50_000, 90_000], [0.5, 0.79], [0.31, 0.5]), [NOT_MET] * 4),
    # on the bound itself: <= and >= hold there, < does not
    (([1.8, 2.0], [100_000, 100_000], [0.8, 0.9], [0.2, 0.3]), [HELD, HELD, HELD, AT_THRESHOLD]),
])
def test_verdicts_follow_the_whole_spread(figures, verdicts):
    bench = _bench(*figures)
    assert [judge(aim, bench)[2] for aim in AIMS] == verdicts
    page = render(bench, "x.json")
    for aim, verdict in zip(AIMS, verdicts):
        row = next(line for line in page.splitlines() if line.startswith(f"| {aim.text} |"))
        assert row.endswith(f"| **{verdict}** |")


def test_no_spread_is_not_judged_and_errors_are_named():
    bench = _bench([1.5, 1.9], [120_000, 150_000], [0.85, 0.95], [0.2, 0.29])
    partial = copy.deepcopy(bench)
    del partial["session"]["stub_pty_vs_bare_pty"]["per_batch_ratio_range"]
    partial["session"]["hil_run_startup"] = {"error": "hil not found"}
    got = [judge(aim, partial)[2] for aim in AIMS]
    assert got[:2] == [HELD, HELD]
    assert got[2] == NOT_JUDGED
    assert got[3] == "not measured: hil not found"


def test_the_hostile_board_soak_is_a_table_of_its_figures():
    soak = {"sessions": 2000, "crashes": 0, "hangs": 0, "unnamed": 0, "logs_readable": 2000,
            "not_safe": 0, "ends_by_kind": {"ok": 1500, "watchdog": 500},
            "realtime": {"sessions": 200, "crashes": 1, "hangs": 0, "unnamed": 0,
                         "logs_readable": 200, "not_safe": 0}}
    page = render({"hostile_board": soak}, "x.json")
    assert "| sessions | 2,000 | 200 |" in page
    assert "| crashes (an exception the bench does not name) | 0 | 1 |" in page
    assert "How the lockstep sessions ended: ok 1500, watchdog 500." in page
    assert "Not measured in this JSON" in render({}, "x.json")
