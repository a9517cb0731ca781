"""What a plan's HTML report costs (issue 18's start-up aim): importing the figure code in a
fresh interpreter (the SVG module the reports use against matplotlib's Figure + Agg canvas,
which they used before), and writing the reports of the steady-state plan (9 checks with a
figure each and 4 plots: the 13 figures the output counts, ~10,500 samples a signal) from a
finished run. Medians of `runs` each.
"""
from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PLAN = ROOT / "test_plans" / "02_steady_state_3000rpm.yaml"

_IMPORTS = {
    "svg (hil.reports.svg)": "import hil.reports.svg",
    "matplotlib Figure + Agg": ("from matplotlib.figure import Figure\n"
                                "from matplotlib.backends.backend_agg import FigureCanvasAgg"),
}


def import_seconds(statement: str, runs: int) -> float:
    """Median wall time of `statement` in a fresh interpreter, less the interpreter's own
    start-up (numpy imported first in both, as the bench always has it loaded)."""
    code = ("import time, numpy\nt0 = time.perf_counter()\n" + statement +
            "\nprint(time.perf_counter() - t0)")
    times = [float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                  check=True, cwd=ROOT).stdout) for _ in range(runs)]
    return statistics.median(times)


def report_seconds(runs: int) -> dict:
    from hil.plans.format import load_plan
    from hil.reports.html import write_reports
    from hil.run.runner import run_plan

    plan = load_plan(PLAN)
    with tempfile.TemporaryDirectory() as tmp:
        result, signals = run_plan(plan, out_dir=Path(tmp) / "run")
        times = []
        for i in range(runs):
            t0 = time.perf_counter()
            paths = write_reports(result, signals, Path(tmp) / f"r{i}", plan=plan)
            times.append(time.perf_counter() - t0)
        html_bytes = paths["html"].stat().st_size
    return {"median_s": round(statistics.median(times), 3), "runs": runs,
            "checks": len(plan.checks), "figures": len(plan.checks) + len(plan.plots),
            "html_kB": round(html_bytes / 1024)}


def run(quick: bool = False) -> dict:
    runs = 3 if quick else 7
    out = {"import_s": {name: round(import_seconds(stmt, runs), 4)
                        for name, stmt in _IMPORTS.items()},
           "steady_state_report": report_seconds(runs)}
    return out


if __name__ == "__main__":
    import json

    print(json.dumps(run(quick="--quick" in sys.argv), indent=2))
