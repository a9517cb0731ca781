"""A sweep's results on disk, one row per run.

    OUT/sweep.json        what was swept (name, files and their SHA-256, seed, run count)
    OUT/results.jsonl     one JSON row per finished run, appended and flushed as runs finish:
                          what --resume reads (a torn last line from a kill is ignored).
                          A journal: rows in the order runs finished, which with several
                          workers is the machine's (a row waiting for a slower one would be
                          lost to a kill); --resume rewrites the rows it keeps by index
    OUT/results.json      the same rows as JSON, sorted by run index: diff this one
    OUT/results.parquet   the table: one row per run, columns index, plan, point, sample,
                          seed, param.<name>..., outcome, reason, lost, wall_s, sim_s, log,
                          worker, check.<name>.measured / .outcome ... (pyarrow)
    OUT/summary.json      yields with Wilson intervals and drivers (hil.sweep.summary)
    OUT/index.html        the yield table and scatter plots (hil.sweep.html)
    OUT/junit.xml         one test case per check, aggregated over the runs
    OUT/runs/NNNNNN/      the MCAP logs kept (failed runs and a sample of passing ones)

Parquet because the table is wide and typed (a float column per check and per parameter),
read column by column by pandas, polars, DuckDB or Arrow without a schema guess, and
compressed; JSON next to it for people and tools without Arrow.
"""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

from configfile.source import ConfigError


def file_digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def manifest(sweep, total: int) -> dict:
    files = [sweep.source_path, *sweep.plan_paths]
    return {"name": sweep.name, "seed": sweep.seed, "runs": total,
            "files": {str(Path(f).resolve()): file_digest(f) for f in files}}


class ResultStore:
    def __init__(self, out: Path):
        self.out = Path(out)
        self.jsonl = self.out / "results.jsonl"
        self._fh = None

    def open(self, info: dict, resume: bool) -> dict[int, dict]:
        """Existing rows by index (resume), after checking that the sweep is the same one."""
        self.out.mkdir(parents=True, exist_ok=True)
        man = self.out / "sweep.json"
        rows: dict[int, dict] = {}
        if self.jsonl.exists() and self.jsonl.stat().st_size > 0:
            if not resume:
                raise ConfigError(f"{self.out} already holds results of a sweep: --resume to "
                                  f"continue it, or another --out", str(self.jsonl))
            old = json.loads(man.read_text()) if man.exists() else None
            if old != info:
                raise ConfigError("--resume: the sweep or its plans changed since these results "
                                  "were written (sweep.json differs)", str(man))
            rows = self.read_rows()
        man.write_text(json.dumps(info, indent=2) + "\n")
        # A torn last line (killed mid-write) is dropped by rewriting the good rows.
        with open(self.jsonl, "w") as fh:
            for r in sorted(rows.values(), key=lambda r: r["index"]):
                fh.write(json.dumps(r) + "\n")
        self._fh = open(self.jsonl, "a", buffering=1)
        return rows

    def read_rows(self) -> dict[int, dict]:
        rows: dict[int, dict] = {}
        if not self.jsonl.exists():
            return rows
        for line in self.jsonl.read_text().splitlines():
            try:
                r = json.loads(line)
            except json.JSONDecodeError:
                continue
            rows.setdefault(r["index"], r)    # a run is recorded once
        return rows

    def append(self, row: dict) -> None:
        self._fh.write(json.dumps(row) + "\n")
        self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def flat_rows(rows: list[dict], parameters: list[str]) -> list[dict[str, Any]]:
    check_names: list[str] = []
    for r in rows:
        for c in r["checks"]:
            if c["name"] not in check_names:
                check_names.append(c["name"])
    flat = []
    for r in sorted(rows, key=lambda r: r["index"]):
        d: dict[str, Any] = {k: r.get(k) for k in ("index", "plan", "plan_file", "point", "sample",
                                                    "seed", "outcome", "reason", "lost", "wall_s",
                                                    "run_wall_s", "sim_s", "log", "worker")}
        for p in parameters:
            d[f"param.{p}"] = r["params"].get(p)
        by = {c["name"]: c for c in r["checks"]}
        for name in check_names:
            c = by.get(name)
            d[f"check.{name}.measured"] = None if c is None else c["measured"]
            d[f"check.{name}.outcome"] = None if c is None else c["outcome"]
        flat.append(d)
    return flat


def write_table(rows: list[dict], parameters: list[str], out: Path) -> tuple[Path, Path]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    flat = flat_rows(rows, parameters)
    columns = list(flat[0]) if flat else ["index"]
    arrays = {}
    for col in columns:
        values = [f.get(col) for f in flat]
        try:
            arrays[col] = pa.array(values)
        except (pa.ArrowInvalid, pa.ArrowTypeError):     # mixed types (a choice of 1 and "a")
            arrays[col] = pa.array([None if v is None else str(v) for v in values])
    pq.write_table(pa.table(arrays), out / "results.parquet")
    (out / "results.json").write_text(json.dumps(
        sorted(rows, key=lambda r: r["index"]), indent=1, default=_json_default) + "\n")
    return out / "results.parquet", out / "results.json"


def _json_default(x):
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    raise TypeError(type(x).__name__)
