"""The runs of a sweep: every plan x every grid point x `runs` samples, in a fixed order.

Everything here is a function of the sweep file alone, never of the executor: the run list,
each run's parameter values and each run's noise seed (``run_seed(sweep.seed, index)``), so
one worker and a hundred produce the same table.

Sampled distributions are drawn through their inverse CDF from a u in (0, 1):

- Monte Carlo: u from a PCG64 stream seeded by (sweep seed, 1, sample number, parameter
  number): sample k has the same values whatever the number of samples.
- Latin hypercube: for each parameter the unit interval is cut into `runs` strata, each
  stratum used once (a seeded permutation), u uniform inside its stratum.

Sample k has the same values for every plan and every grid point (common random numbers: a
difference between two plans is not sampling noise).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from statistics import NormalDist
from typing import Any

import numpy as np

from hil.sweep.format import Parameter, Sweep

_STD = NormalDist()


@dataclass(frozen=True)
class RunSpec:
    index: int
    plan_path: Path
    point: int                 # grid point number
    sample: int                # sample number within the grid point
    seed: int
    values: dict[str, Any]     # swept parameters only (the sweep's `set` values apply too)


def run_seed(sweep_seed: int, index: int) -> int:
    """The run's noise seed: a 31-bit number from (sweep seed, run index), independent of
    everything else (workers, order of completion, resumes)."""
    return int(np.random.SeedSequence([sweep_seed, 0, index]).generate_state(1)[0] & 0x7FFFFFFF)


def inverse_cdf(p: Parameter, u: float) -> Any:
    if p.kind == "uniform":
        lo, hi = float(p.spec["low"]), float(p.spec["high"])
        return lo + u * (hi - lo)
    if p.kind == "normal":
        m, sd = float(p.spec["mean"]), float(p.spec["sd"])
        a = _STD.cdf((float(p.spec["low"]) - m) / sd) if "low" in p.spec else 0.0
        b = _STD.cdf((float(p.spec["high"]) - m) / sd) if "high" in p.spec else 1.0
        q = min(max(a + u * (b - a), 1e-15), 1.0 - 1e-15)
        x = m + sd * _STD.inv_cdf(q)
        if "low" in p.spec:
            x = max(x, float(p.spec["low"]))
        if "high" in p.spec:
            x = min(x, float(p.spec["high"]))
        return x
    if p.kind == "choice":
        values, weights = p.choices()
        total = sum(weights)
        acc = 0.0
        for v, w in zip(values, weights):
            acc += w / total
            if u < acc:
                return v
        return next(v for v, w in zip(reversed(values), reversed(weights)) if w > 0)
    raise ValueError(f"{p.name}: {p.kind} is not sampled")


def unit_samples(sweep: Sweep) -> np.ndarray:
    """u in (0, 1), shape (runs, number of sampled parameters)."""
    sampled = sweep.sampled
    n, d = sweep.runs, len(sampled)
    if d == 0:
        return np.zeros((n, 0))
    if sweep.sampling == "latin_hypercube":
        rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([sweep.seed, 2])))
        u = np.empty((n, d))
        for j in range(d):
            u[:, j] = (rng.permutation(n) + rng.random(n)) / n
        return u
    u = np.empty((n, d))
    for k in range(n):
        for j in range(d):
            rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([sweep.seed, 1, k, j])))
            u[k, j] = rng.random()
    return u


def grid_points(sweep: Sweep) -> list[dict[str, Any]]:
    grid = sweep.grid
    if not grid:
        return [{}]
    return [dict(zip((p.name for p in grid), combo))
            for combo in itertools.product(*(p.grid_values() for p in grid))]


def expand(sweep: Sweep) -> list[RunSpec]:
    u = unit_samples(sweep)
    samples = [{p.name: inverse_cdf(p, float(u[k, j])) for j, p in enumerate(sweep.sampled)}
               for k in range(sweep.runs)]
    points = grid_points(sweep)
    runs: list[RunSpec] = []
    for plan_path in sweep.plan_paths:
        for gi, point in enumerate(points):
            for k, sample in enumerate(samples):
                index = len(runs)
                runs.append(RunSpec(index, plan_path, gi, k, run_seed(sweep.seed, index),
                                    {**point, **sample}))
    return runs


def keep_passing_log(sweep_seed: int, index: int, fraction: float) -> bool:
    """Whether a passing run's log is kept: a deterministic draw per run."""
    if fraction >= 1.0:
        return True
    if fraction <= 0.0:
        return False
    u = np.random.Generator(np.random.PCG64(np.random.SeedSequence([sweep_seed, 3, index]))).random()
    return bool(u < fraction) and not math.isnan(u)
