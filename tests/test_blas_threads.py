"""hil sets OpenBLAS to one thread before numpy loads (hil/__init__.py): no idle BLAS worker
spinning beside a lockstep run; a user's own OPENBLAS_NUM_THREADS still wins."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

_THREADS = "import hil, numpy, os; print(len(os.listdir('/proc/self/task')))"
# what bench._period_worker and bench.session do: plant_rt (numpy) before anything of hil
_BENCH_THREADS = "import bench, plant_rt, os; print(len(os.listdir('/proc/self/task')))"


def _threads(env_value: str | None, code: str = _THREADS) -> int:
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    if env_value is not None:
        env["OPENBLAS_NUM_THREADS"] = env_value
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True, timeout=60)
    return int(out.stdout)


@pytest.mark.skipif(not os.path.isdir("/proc/self/task") or (os.cpu_count() or 1) < 2,
                    reason="counts threads through /proc; OpenBLAS starts none on one CPU")
def test_importing_hil_first_leaves_numpy_with_one_blas_thread_unless_the_user_asks():
    assert _threads(None) == 1
    assert _threads("2") == 2       # the user's setting: OpenBLAS's worker thread is there


@pytest.mark.skipif(not os.path.isdir("/proc/self/task") or (os.cpu_count() or 1) < 2,
                    reason="counts threads through /proc; OpenBLAS starts none on one CPU")
def test_the_benchmarks_get_one_blas_thread_even_when_they_import_the_plant_first():
    assert _threads(None, _BENCH_THREADS) == 1
