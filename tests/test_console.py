"""The run console (hil/run/console.py, issue 17): notable events printed as they happen,
once and then rate-limited per kind, nothing lost at the end; and a real run's board FAULT and
injected faults reaching it through the session's event listeners."""
from __future__ import annotations

import re
from pathlib import Path

from hil.plans.format import load_plan
from hil.run.console import EventConsole
from hil.run.runner import run_plan

REPO = Path(__file__).resolve().parents[1]


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_a_burst_costs_a_few_lines_and_loses_no_count():
    """1,000 missed answers over 2.5 s of wall time, one every 2.5 ms: the first at once, one
    line per second after it (each saying how many it held back), the rest at close; the
    counts printed add up to 1,000."""
    lines: list[str] = []
    clock = Clock()
    console = EventConsole(write=lines.append, interval_s=1.0, clock=clock)
    for i in range(1000):
        clock.now = i * 0.0025
        console(i * 50e-6, "missed", {"period": i, "samples_sent": 3})
        console.tick()
    console.close()
    assert lines[0] == "hil: t = 0.000000 s: missed SAMPLE answer (period 0; samples_sent 3)"
    assert len(lines) <= 5
    assert events_told(lines) == 1000


def events_told(lines: list[str]) -> int:
    """How many events the lines account for: a line of one event, plus the N it says it held
    back ("...; and N more since the last line"), or a summary of N ("N more: ...")."""
    total = 0
    for line in lines:
        held = re.search(r"; and (\d+) more since the last line$", line)
        summary = re.match(r"hil: (\d+) more: ", line)
        total += int(summary.group(1)) if summary else 1 + (int(held.group(1)) if held else 0)
    return total


def test_kinds_are_limited_apart_and_the_sessions_own_first_warning_is_not_repeated():
    lines: list[str] = []
    clock = Clock()
    console = EventConsole(write=lines.append, interval_s=1.0, clock=clock)
    console(0.1, "board_fault", {"code": 2, "period": 2000})     # the session printed this one
    console(0.1, "deadline_miss", {"period": 2000, "late_us": 61.5})
    console(0.2, "fault", {"action": "inject", "name": "link_drop", "period": 4000})
    console(0.3, "fault", {"action": "lift", "name": "link_drop", "period": 6000})
    console(0.3, "command", {"speed_ref_rpm": 1500})             # not a notable kind
    clock.now = 2.0
    console(0.4, "board_fault", {"code": 2, "period": 8000})
    console.close()
    assert lines == [
        "hil: t = 0.100000 s: real-time deadline miss (period 2000; late_us 61.5)",
        "hil: t = 0.200000 s: fault link_drop injected (period 4000)",
        "hil: t = 0.300000 s: fault link_drop lifted (period 6000)",
        "hil: t = 0.400000 s: board FAULT (code 2; period 8000)",
    ]


def test_a_run_tells_the_console_about_its_faults(tmp_path):
    """The encoder-loss plan injects a fault and the board answers with FAULT ENCODER_LOSS:
    the console hears both (the FAULT's first occurrence the session prints itself)."""
    heard: list[tuple[str, dict]] = []
    plan = load_plan(REPO / "test_plans" / "faults" / "02_encoder_loss_detected.yaml")
    result, _ = run_plan(plan, out_dir=tmp_path, reports=False,
                         console=lambda t, kind, data: heard.append((kind, data)))
    assert result.outcome.passed
    kinds = [k for k, _ in heard]
    assert "board_fault" in kinds
    assert any(k == "fault" and d["action"] == "inject" and d["name"] == "encoder_lost"
               for k, d in heard)
    lines: list[str] = []
    console = EventConsole(write=lines.append)
    for kind, data in heard:
        console(0.0, kind, data)
    assert any("fault encoder_lost injected" in line for line in lines)
