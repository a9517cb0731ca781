"""python -m bench [NAME ...] [--quick]: prints the named benchmarks' figures as JSON.

python -m bench perf_page BENCH.json [--out docs/performance.md]: the performance page of
one such JSON (bench/_perf_page.py).
"""
from __future__ import annotations

import argparse
import datetime
import importlib
import json
import os
import pkgutil
import platform
import sys

import bench


def available() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(bench.__path__) if not m.name.startswith("_"))


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "CPU model not known"


def run_record(argv: list[str]) -> dict:
    """Where and when the figures were measured: the page made from them names it."""
    return {"date_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "command": "python -m bench " + " ".join(argv),
            "machine": f"{_cpu_model()}, {os.cpu_count()} CPUs ({platform.machine()})",
            "system": platform.platform(), "python": platform.python_version()}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["perf_page"]:
        from bench._perf_page import main as perf_page_main

        return perf_page_main(argv[1:])
    parser = argparse.ArgumentParser(prog="python -m bench", description=__doc__)
    parser.add_argument("names", nargs="*", help=f"benchmarks to run (default all): {', '.join(available())}")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    args = parser.parse_args(argv)
    names = args.names or available()
    unknown = [n for n in names if n not in available()]
    if unknown:
        parser.error(f"unknown benchmark {', '.join(unknown)}; known: {', '.join(available())}")
    results = {"_run": run_record(argv)}
    for name in names:
        module = importlib.import_module(f"bench.{name}")
        results[name] = module.run(quick=args.quick)
        print(f"bench {name}: done", file=sys.stderr)
    print(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
