"""`hil sweep`: expand a sweep, run what is not yet done, write the table, summary and pages."""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

from configfile.source import ConfigError
from hil.sweep.executors import DaskExecutor, LocalExecutor
from hil.sweep.format import Sweep, load_sweep
from hil.sweep.html import write_html, write_junit
from hil.sweep.results import ResultStore, manifest, write_table
from hil.sweep.sampling import expand, keep_passing_log
from hil.sweep.summary import summarize


def tasks_for(sweep: Sweep, out: Path) -> list[dict]:
    return [{"index": r.index, "plan_path": str(r.plan_path), "point": r.point, "sample": r.sample,
             "seed": r.seed, "values": r.values, "fixed": dict(sweep.fixed), "link": sweep.link,
             "board": None if sweep.board_path is None else str(sweep.board_path),
             "out_dir": str((out / "runs").resolve()), "keep_failed": sweep.keep_failed_logs,
             "keep_passing": keep_passing_log(sweep.seed, r.index, sweep.keep_passing_logs)}
            for r in expand(sweep)]


class _Progress:
    """rich progress: runs done, rate, ETA, running yield; nothing when not a terminal."""

    def __init__(self, total: int, done: int, enabled: bool):
        self.bar = None
        self.passed = self.judged = 0
        if not enabled or not sys.stderr.isatty():
            return
        from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                   TimeRemainingColumn)

        self.bar = Progress(TextColumn("sweep"), BarColumn(), MofNCompleteColumn(),
                            TextColumn("{task.speed} runs/s"),
                            TextColumn("ETA"), TimeRemainingColumn(),
                            TextColumn("yield {task.fields[yield_text]}"), transient=True)
        self.task = self.bar.add_task("sweep", total=total, completed=done, yield_text="-")
        self.bar.start()

    def update(self, row: dict) -> None:
        if not row.get("lost"):
            self.judged += 1
            self.passed += row["outcome"] in ("PASS", "MARGINAL")
        if self.bar is not None:
            self.bar.update(self.task, advance=1,
                            yield_text=f"{100 * self.passed / self.judged:.1f} %" if self.judged else "-")

    def stop(self) -> None:
        if self.bar is not None:
            self.bar.stop()


def check_programs_allowed(sweep: Sweep, allow_programs: bool) -> None:
    """A sweep whose link runs a program it names (exec:, lib:, qemu:) runs only when the
    user says so: running someone else's sweep file must not run their program unasked."""
    if sweep.program_link and not allow_programs:
        raise ConfigError(f"link '{sweep.link}' runs the program it names on this machine; "
                          f"run it only if you trust it: hil sweep --allow-programs",
                          str(sweep.source_path), sweep.link_line, "sweep.link")


def run_sweep(sweep: Sweep, out: Path, workers: int = 1, cluster: str | None = None,
              resume: bool = False, progress: bool = True, stall_timeout_s: float = 600.0,
              allow_programs: bool = False) -> dict:
    check_programs_allowed(sweep, allow_programs)
    out = Path(out)
    tasks = tasks_for(sweep, out)
    info = manifest(sweep, len(tasks))
    store = ResultStore(out)
    rows = store.open(info, resume)
    todo = [t for t in tasks if t["index"] not in rows]
    executor = (DaskExecutor(cluster, retries=sweep.retries, stall_timeout_s=stall_timeout_s)
                if cluster else LocalExecutor(workers, retries=sweep.retries,
                                              stall_timeout_s=stall_timeout_s))
    bar = _Progress(len(tasks), len(rows), progress)
    t0 = time.monotonic()

    def on_row(row: dict) -> None:
        if row["index"] in rows:        # a run is recorded exactly once
            return
        rows[row["index"]] = row
        store.append(row)
        bar.update(row)

    try:
        if todo:
            executor.run(todo, on_row)
    finally:
        bar.stop()
        store.close()
    wall = time.monotonic() - t0
    return finish(sweep, out, info, list(rows.values()), {"executor": executor.describe(),
                                                          "wall_s": wall, "ran": len(todo)})


def finish(sweep: Sweep, out: Path, info: dict, rows: list[dict], extra: dict) -> dict:
    params = [p.name for p in sweep.parameters]
    write_table(rows, params, out)
    summary = summarize(rows, params)
    summary.update(extra)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=_nan) + "\n")
    write_html(info, summary, rows, out)
    write_junit(info, summary, out)
    return summary


def _nan(x):
    return None if isinstance(x, float) and math.isnan(x) else str(x)


def sweep_command(args) -> int:
    sweep = load_sweep(args.sweep)
    out = args.out or Path("out") / "sweeps" / sweep.name
    summary = run_sweep(sweep, out, workers=args.workers, cluster=args.cluster, resume=args.resume,
                        progress=not args.no_progress,
                        allow_programs=getattr(args, "allow_programs", False))
    for p in summary["plans"]:
        lo, hi = p["ci_low"], p["ci_high"]
        print(f"{p['plan']}: yield {p['passed']}/{p['judged']} = {100 * p['yield']:.1f} % "
              f"(95 % CI {100 * lo:.1f} - {100 * hi:.1f} %), lost {p['lost']}")
    for c in [c for c in summary["checks"] if c["failed"]][:10]:
        d = c["drivers"][0]["parameter"] if c["drivers"] else "-"
        print(f"  FAIL {c['failed']}/{c['evaluated']} {c['plan']}: {c['check']} (strongest: {d})")
    print(f"{summary['runs']} runs ({summary['ran']} now, {summary['executor']}, "
          f"{summary['wall_s']:.1f} s): {out / 'index.html'}, {out / 'results.parquet'}, "
          f"{out / 'junit.xml'}")
    if summary["lost"]:
        return 2
    return 0 if all(p["passed"] == p["judged"] for p in summary["plans"]) else 1
