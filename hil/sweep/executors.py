"""Where the runs run: local processes (default) or a Dask distributed cluster.

Both take plain task dicts (hil.sweep.worker.run_one) and hand each finished row to a callback
in the calling process, which alone writes results. A run is never silently missing: when it
cannot be run (its retries spent on dying workers, or no result within the stall bound) it
comes back as a row with ``lost: True``, outcome ERROR and the reason.

- LocalExecutor: a concurrent.futures process pool (spawned processes: nothing to install or
  start). A pool process that dies breaks the pool; the runs that were in flight count one
  attempt each and are resubmitted to a new pool until their retries are spent.
- DaskExecutor: a running scheduler (``--cluster tcp://HOST:8786``). Dask's own machinery
  retries: ``submit(..., retries=N)`` re-runs a task that raised, and the scheduler
  reschedules a task whose worker died, up to ``distributed.scheduler.allowed-failures``
  deaths (default 3), after which the future raises KilledWorker: that run is recorded lost.
"""
from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import time
import uuid
from typing import Callable, Iterable

from hil.sweep.worker import run_one

STALL_TIMEOUT_S = 600.0     # no result at all for this long: the remaining runs are lost


def lost_row(task: dict, reason: str) -> dict:
    return {"index": task["index"], "plan_file": task["plan_path"], "plan": None,
            "point": task["point"], "sample": task["sample"], "seed": task["seed"],
            "params": dict(task["values"]), "outcome": "ERROR", "reason": reason, "checks": [],
            "sim_s": 0.0, "run_wall_s": 0.0, "wall_s": 0.0, "log": None, "worker": None,
            "lost": True}


class LocalExecutor:
    def __init__(self, workers: int, retries: int = 2, stall_timeout_s: float = STALL_TIMEOUT_S,
                 fn: Callable[[dict], dict] = run_one):
        self.workers = max(1, int(workers))
        self.retries = retries
        self.stall_timeout_s = stall_timeout_s
        self.fn = fn

    def describe(self) -> str:
        return f"{self.workers} local process{'es' if self.workers > 1 else ''}"

    def run(self, tasks: Iterable[dict], on_row: Callable[[dict], None]) -> None:
        """Runs the tasks on a process pool. A worker that dies breaks the whole pool, and the
        pool cannot say which task killed it: every task in flight then becomes a suspect and
        runs again alone, where only the one that kills its worker is charged an attempt (an
        innocent run never loses a retry to another's crash)."""
        pending = list(tasks)[::-1]          # pop() takes them in index order
        suspects: list[dict] = []
        attempts: dict[int, int] = {}
        ctx = multiprocessing.get_context("spawn")
        while pending or suspects:
            if suspects:
                self._run_alone(suspects.pop(), attempts, suspects, on_row, ctx)
                continue
            pool = cf.ProcessPoolExecutor(self.workers, mp_context=ctx)
            in_flight: dict[cf.Future, dict] = {}
            broken = False
            try:
                while (pending or in_flight) and not broken:
                    while pending and len(in_flight) < 2 * self.workers:
                        task = pending.pop()
                        in_flight[pool.submit(self.fn, task)] = task
                    done, _ = cf.wait(in_flight, timeout=self.stall_timeout_s,
                                      return_when=cf.FIRST_COMPLETED)
                    if not done:
                        for task in in_flight.values():
                            on_row(lost_row(task, f"no result within {self.stall_timeout_s:g} s"))
                        in_flight.clear()
                        broken = True
                        break
                    # cf.wait hands a set: in index order, so that one worker writes its
                    # rows in order (several finish in any order: results.py)
                    for fut in sorted(done, key=lambda f: in_flight[f]["index"]):
                        task = in_flight.pop(fut)
                        try:
                            on_row(fut.result())
                        except cf.process.BrokenProcessPool:
                            broken = True
                            suspects.append(task)
                        except Exception as exc:  # noqa: BLE001 - the worker failed, not the plan
                            self._retry(task, attempts, pending, on_row, f"{type(exc).__name__}: {exc}")
                if broken:
                    suspects.extend(in_flight.values())
                    in_flight.clear()
            finally:
                pool.shutdown(wait=not broken, cancel_futures=True)

    def _run_alone(self, task, attempts, suspects, on_row, ctx) -> None:
        """One task on a pool of its own: if its worker dies now, the task killed it."""
        pool = cf.ProcessPoolExecutor(1, mp_context=ctx)
        broken = False
        try:
            fut = pool.submit(self.fn, task)
            done, _ = cf.wait([fut], timeout=self.stall_timeout_s)
            if not done:
                broken = True
                on_row(lost_row(task, f"no result within {self.stall_timeout_s:g} s"))
                return
            try:
                on_row(fut.result())
            except cf.process.BrokenProcessPool:
                broken = True
                self._retry(task, attempts, suspects, on_row, "a worker process died")
            except Exception as exc:  # noqa: BLE001
                self._retry(task, attempts, suspects, on_row, f"{type(exc).__name__}: {exc}")
        finally:
            pool.shutdown(wait=not broken, cancel_futures=True)

    def _retry(self, task, attempts, pending, on_row, reason):
        n = attempts[task["index"]] = attempts.get(task["index"], 0) + 1
        if n > self.retries:
            on_row(lost_row(task, f"{reason}; gave up after {n} attempts"))
        else:
            pending.append(task)


class DaskExecutor:
    def __init__(self, address: str, retries: int = 2, stall_timeout_s: float = STALL_TIMEOUT_S,
                 connect_timeout_s: float = 10.0, fn: Callable[[dict], dict] = run_one):
        self.address = address
        self.retries = retries
        self.stall_timeout_s = stall_timeout_s
        self.connect_timeout_s = connect_timeout_s
        self.fn = fn

    def describe(self) -> str:
        return f"Dask cluster {self.address}"

    def run(self, tasks: Iterable[dict], on_row: Callable[[dict], None]) -> None:
        from distributed import Client, wait
        from distributed.client import FutureCancelledError

        try:
            client = Client(self.address, timeout=self.connect_timeout_s)  # distributed.wait needs the default client
        except OSError as exc:
            raise RuntimeError(f"cannot reach the Dask scheduler at {self.address}: {exc}") from None
        token = uuid.uuid4().hex[:8]
        try:
            futures = {client.submit(self.fn, task, key=f"hil-sweep-{token}-{task['index']}",
                                     retries=self.retries, pure=False): task for task in tasks}
            remaining = set(futures)
            while remaining:
                try:
                    done, remaining = wait(remaining, timeout=self.stall_timeout_s,
                                           return_when="FIRST_COMPLETED")
                except TimeoutError:
                    for fut in remaining:
                        on_row(lost_row(futures[fut], f"no result within {self.stall_timeout_s:g} s"))
                        fut.cancel()
                    break
                for fut in done:
                    task = futures[fut]
                    if fut.status == "finished":
                        on_row(fut.result())
                        continue
                    try:
                        exc = fut.exception(timeout=self.stall_timeout_s)
                    except FutureCancelledError:
                        exc = "cancelled"
                    reason = f"{type(exc).__name__}: {exc}" if not isinstance(exc, str) else exc
                    on_row(lost_row(task, f"Dask gave up on the run ({reason})"))
                    fut.release()
        finally:
            client.close(timeout=self.connect_timeout_s)
