"""Sweeps: one or more plans run many times over a parameter space (`hil sweep`, issue 16).

format (the sweep file), sampling (runs, values, seeds), worker (one run), executors (local
processes, Dask), results (Parquet + JSON rows, resume), summary (yields, Wilson, drivers),
html (page, JUnit), run (the command). docs/scale.md: clusters and labs of physical benches.
"""
from hil.sweep.format import Sweep, load_sweep, looks_like_sweep, parse_sweep

__all__ = ["Sweep", "load_sweep", "looks_like_sweep", "parse_sweep"]
