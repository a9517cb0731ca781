"""Bench sessions: lockstep periods per second per link, with and without the MCAP log,
against the bare pseudo-terminal round trip measured in the same run; and the real-time
clock: the real-time factor at the paper's 50 us and the fastest period it holds with no
missed deadline.

Every rate is the median of several batches of one session (the session is opened once
per configuration, so process start-up and the handshake are not counted).
"""
from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

from plant_rt import load_profile

from hil.session.realtime import held
from hil.session.bench_session import BenchSession, SessionConfig

LINKS = ("stub", "stub-pty", "stub-can")

# The shortest plan a check can read (two 50 us periods): hil_run_startup, startup_side_by_side.
TWO_PERIOD_PLAN = ("name: two-periods\nsteps:\n  - run: {duration_s: 100.0e-6}\n"
                   "  - check: {name: ran, kind: final_value, signal: plant.speed_rpm, "
                   "limits: {low: -1, high: 1, unit: rpm}}\n")


def lockstep_rate(link: str, log: bool, periods: int, batches: int,
                  controller: dict | None = None) -> dict:
    """``controller``: settings pushed on top of the stub's board file (e.g. the TELEMETRY rate)."""
    from hil.session.board_params import default_board

    profile = load_profile()
    board = default_board(link).with_settings(controller)
    with tempfile.TemporaryDirectory() as tmp:
        log_path = Path(tmp) / "bench.mcap" if log else None
        with BenchSession(profile, SessionConfig(link=link, log_path=log_path,
                                                 board=board)) as session:
            hold = session.cpu_latency.status
            session.send_command(enable=True, speed_source="ekf", speed_ref_rpm=3000)
            session.run_periods(periods // 4)  # warm-up
            rates = []
            for _ in range(batches):
                t0 = time.perf_counter()
                session.run_periods(periods)
                rates.append(periods / (time.perf_counter() - t0))
    rate = statistics.median(rates)
    return {"periods_per_s": round(rate), "us_per_period": round(1e6 / rate, 2),
            "real_time_factor_at_50us": round(rate * profile.control_period_s, 3),
            "cpu_dma_latency": hold}


def _plant_replay(plant, gates: list[int]):
    """A function that drives `plant` as the session does (sample, truth, step) through the
    switch words `gates` once and returns the periods/s it took."""
    def replay() -> float:
        sample, step, truth = plant.sample, plant.step, plant.truth
        t0 = time.perf_counter()
        for g in gates:
            sample()
            truth()
            step(g)
        return len(gates) / (time.perf_counter() - t0)
    return replay


def plant_only_rate(periods: int, batches: int) -> dict:
    """The plant alone, as the session drives it (sample, step, truth per period), replaying
    the switch words the stub chose in a 3000 rpm EKF run: the floor under any lockstep rate."""
    from plant_rt import Plant

    profile = load_profile()
    with BenchSession(profile, SessionConfig(link="stub")) as session:
        session.send_command(enable=True, speed_source="ekf", speed_ref_rpm=3000)
        session.run_periods(periods)
        gates = [int(row[4]) for row in session.recorder.telemetry_rows[-periods:]]
    replay = _plant_replay(Plant(profile, seed=0), gates)
    rate = statistics.median(replay() for _ in range(batches))
    return {"periods_per_s": round(rate), "us_per_period": round(1e6 / rate, 2)}


def _to_speed(session: BenchSession, periods: int) -> None:
    """Starts `session` and runs it to 3000 rpm on the EKF's speed and past the warm-up (4 x
    `periods`), as the interleaved comparisons begin."""
    session.start()
    session.send_command(enable=True, speed_source="ekf", speed_ref_rpm=3000)
    session.run_periods(4 * periods)


def _batch_rate(session: BenchSession, periods: int) -> float:
    """Periods/s of `periods` more periods of `session`."""
    t0 = time.perf_counter()
    session.run_periods(periods)
    return periods / (time.perf_counter() - t0)


def stub_log_plant_interleaved(periods: int, batches: int) -> dict:
    """Issue 18's headline trio side by side: `stub`, `stub` with the full log, and the plant
    alone (sample, truth, step, replaying the stub's switch words), in short batches taken in
    turn, so that the VM's drift (10-30 % over seconds here) falls on all three alike; medians
    of each and the ratios from them. (Measured one after the other, as lockstep_rate does for
    the other links, the log's cost moved from 4 to 11 us between runs.)"""
    from plant_rt import Plant

    profile = load_profile()
    with tempfile.TemporaryDirectory() as tmp:
        plain = BenchSession(profile, SessionConfig(link="stub"))
        logged = BenchSession(profile, SessionConfig(link="stub", log_path=Path(tmp) / "bench.mcap"))
        try:
            for s in (plain, logged):
                _to_speed(s, periods)
            gates = [int(row[4]) for row in plain.recorder.telemetry_rows[-periods:]]
            plant_only = _plant_replay(Plant(profile, seed=0), gates)
            rates: dict[str, list[float]] = {"stub": [], "stub+log": [], "plant_only": []}
            for _ in range(batches):
                rates["stub"].append(_batch_rate(plain, periods))
                rates["stub+log"].append(_batch_rate(logged, periods))
                rates["plant_only"].append(plant_only())
        finally:
            plain.close()
            logged.close()
    med = {k: statistics.median(v) for k, v in rates.items()}
    out = {k: {"periods_per_s": round(v), "us_per_period": round(1e6 / v, 2),
               "batch_periods_per_s_range": [round(min(rates[k])), round(max(rates[k]))]}
           for k, v in med.items()}
    out["batches"], out["periods_per_batch"] = batches, periods
    out["log_us_per_period"] = round(1e6 / med["stub+log"] - 1e6 / med["stub"], 2)
    out["stub+log_vs_plant_only"] = round(med["plant_only"] / med["stub+log"], 2)
    # Each round's own ratio (its logged batch against the plant batch right after it): how
    # far one round strays from the medians' ratio.
    ratios = [p / s for p, s in zip(rates["plant_only"], rates["stub+log"])]
    out["per_round_ratio_range"] = [round(min(ratios), 2), round(max(ratios), 2)]
    return out


def log_compression_interleaved(periods: int, batches: int) -> dict:
    """The logged in-process session with its chunks at the default lz4 and uncompressed
    (`hil run --log-compression none`), batches taken in turn: what the compression costs a
    period in the session itself (bench.mcap_logging times the recorder alone), and the
    file bytes a period of each."""
    profile = load_profile()
    rates: dict[str, list[float]] = {"lz4": [], "none": []}
    with tempfile.TemporaryDirectory() as tmp:
        sessions = {c: BenchSession(profile, SessionConfig(link="stub", log_compression=c,
                                                           log_path=Path(tmp) / f"{c}.mcap"))
                    for c in rates}
        try:
            for s in sessions.values():
                _to_speed(s, periods)
            for _ in range(batches):
                for c, s in sessions.items():
                    rates[c].append(_batch_rate(s, periods))
        finally:
            for s in sessions.values():
                s.close()
        total = (4 + batches) * periods
        size = {c: (Path(tmp) / f"{c}.mcap").stat().st_size / total for c in rates}
    med = {c: statistics.median(v) for c, v in rates.items()}
    out = {c: {"periods_per_s": round(v), "us_per_period": round(1e6 / v, 2),
               "file_bytes_per_period": round(size[c], 1)} for c, v in med.items()}
    out["batches"], out["periods_per_batch"] = batches, periods
    out["lz4_us_per_period"] = round(1e6 / med["lz4"] - 1e6 / med["none"], 2)
    out["lz4_period_over_none"] = round(med["none"] / med["lz4"], 3)
    out["lz4_file_over_none"] = round(size["lz4"] / size["none"], 3)
    return out


def timed_hil_run(hil: Path, plan: Path, out_dir: Path, env: dict | None = None) -> tuple[float, str | None]:
    """One `hil run` of `plan` by the console script `hil`, process start to exit: (seconds,
    None), or (seconds, the end of its stderr) when it exited with an error (not 0 or 1)."""
    import subprocess

    t0 = time.perf_counter()
    proc = subprocess.run([str(hil), "run", str(plan), "--out", str(out_dir), "--no-progress"],
                          env=env, capture_output=True, text=True, timeout=120)
    took = time.perf_counter() - t0
    return took, (proc.stderr[-500:] if proc.returncode not in (0, 1) else None)


def hil_run_startup(runs: int) -> dict:
    """Wall time of `hil run` on a two-period plan (the shortest a check can read: process
    start, imports, stub load, handshake, the periods, reports), median of `runs`."""
    import sys

    hil = Path(sys.executable).with_name("hil")     # the console script users run
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "one.yaml"
        path.write_text(TWO_PERIOD_PLAN)
        for i in range(runs + 1):
            took, error = timed_hil_run(hil, path, Path(tmp) / f"out{i}")
            if i:                                   # the first run warms the page cache
                times.append(took)
            if error is not None:
                return {"error": error}
    return {"median_s": round(statistics.median(times), 3), "runs": runs,
            "min_s": round(min(times), 3), "max_s": round(max(times), 3)}


def startup_side_by_side(runs: int) -> dict:
    """Two `hil run` of the two-period plan started together, with OpenBLAS at hil's default
    of one thread (OPENBLAS_NUM_THREADS unset in the children: `import hil` sets it to 1) and
    at OpenBLAS's own default (OPENBLAS_NUM_THREADS = os.cpu_count(), which hil leaves alone):
    the README's case for the one-thread default. Rounds alternate the two settings; each
    process's wall time (start to exit) is timed on its own thread. Medians over `runs` rounds
    (two processes a round) of each, and of the pair's wall time (until both exit); one warm-up
    round of each is not counted."""
    import os
    import sys
    import threading

    hil = Path(sys.executable).with_name("hil")     # the console script users run
    base = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    envs = {"one_blas_thread": base,
            "openblas_default": {**base, "OPENBLAS_NUM_THREADS": str(os.cpu_count() or 1)}}
    times: dict[str, list[float]] = {k: [] for k in envs}
    pairs: dict[str, list[float]] = {k: [] for k in envs}
    errors: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "one.yaml"
        path.write_text(TWO_PERIOD_PLAN)
        n = 0

        def one(env: dict, out: list, slot: int) -> None:
            out[slot], error = timed_hil_run(hil, path, Path(tmp) / f"out{n}_{slot}", env)
            if error is not None:
                errors.append(error)

        for r in range(runs + 1):
            for key, env in envs.items():
                n += 1
                got = [0.0, 0.0]
                threads = [threading.Thread(target=one, args=(env, got, i)) for i in range(2)]
                t0 = time.perf_counter()
                for t in threads:
                    t.start()
                for t in threads:
                    t.join()
                pair = time.perf_counter() - t0
                if errors:
                    return {"error": errors[0]}
                if r:                               # the first round warms the page cache
                    times[key].extend(got)
                    pairs[key].append(pair)
    out: dict = {"rounds": runs, "cpu_count": os.cpu_count()}
    for key in envs:
        out[key] = {"median_s": round(statistics.median(times[key]), 3),
                    "pair_median_s": round(statistics.median(pairs[key]), 3),
                    "min_s": round(min(times[key]), 3), "max_s": round(max(times[key]), 3)}
    out["openblas_default_vs_one_thread"] = round(
        statistics.median(times["openblas_default"]) / statistics.median(times["one_blas_thread"]), 3)
    return out


def stub_pty_vs_bare(hold_cpu_latency: bool, periods: int, batches: int) -> dict:
    """stub-pty lockstep periods against raw round trips of the C echo over another pty.

    Batches alternate (echo, session, echo, ...) so both see the same machine load and the
    same CPU-latency hold: the session takes it when ``hold_cpu_latency`` (the default of
    every session), and the echo batches run inside it.
    """
    from bench.protocol import SAMPLE, _make, _raw_batch, _spawn_echo
    from protocol.codec import FrameEncoder

    _make("build/hil_echo")
    frame = FrameEncoder().encode(SAMPLE)
    echo_proc, echo_link = _spawn_echo(raw=True)
    config = SessionConfig(link="stub-pty", hold_cpu_latency=hold_cpu_latency)
    bare_us, pty_us = [], []
    try:
        with BenchSession(load_profile(), config) as session:
            session.send_command(enable=True, speed_source="ekf", speed_ref_rpm=3000)
            session.run_periods(periods // 4)  # warm-up
            _raw_batch(echo_link, periods // 4, frame)
            for _ in range(batches):
                bare_us.append(_raw_batch(echo_link, periods, frame))
                t0 = time.perf_counter()
                session.run_periods(periods)
                pty_us.append((time.perf_counter() - t0) / periods * 1e6)
            status = session.cpu_latency.status
    finally:
        echo_link.close()
        echo_proc.wait(5)
    bare, pty = statistics.median(bare_us), statistics.median(pty_us)
    return {"cpu_dma_latency": status,
            "bare_pty_round_trips_per_s": round(1e6 / bare), "bare_pty_us": round(bare, 2),
            "stub_pty_periods_per_s": round(1e6 / pty), "stub_pty_us": round(pty, 2),
            "stub_pty_vs_bare": round(bare / pty, 3),
            "per_batch_ratio_range": [round(min(b / p for b, p in zip(bare_us, pty_us)), 3),
                                      round(max(b / p for b, p in zip(bare_us, pty_us)), 3)]}


def realtime_hold(period_s: float, duration_s: float) -> dict:
    """Runs the real-time clock for duration_s against the in-process stub."""
    profile = load_profile()
    config = SessionConfig(link="stub", mode="realtime", realtime_period_s=period_s,
                           realtime_miss_budget=10 ** 9)
    with BenchSession(profile, config) as session:
        session.send_command(enable=True, speed_source="ekf", speed_ref_rpm=3000)
        session.run_periods(round(duration_s / period_s))
        stats = dict(session.rt_stats)
    stats["period_us"] = period_s * 1e6
    return stats


def run(quick: bool = False) -> dict:
    periods, batches = (2000, 3) if quick else (10000, 5)
    out: dict = {"lockstep": {}}
    for link in LINKS:
        for log in (False, True):
            key = f"{link}{'+log' if log else ''}"
            try:
                out["lockstep"][key] = lockstep_rate(link, log, periods if link == "stub" else periods // 5,
                                                     batches)
            except Exception as exc:  # noqa: BLE001 - a missing back end is reported, not fatal
                out["lockstep"][key] = {"error": str(exc)}
    # The floor: the plant alone, and how far the logged in-process session is above it,
    # measured side by side with `stub` and `stub` + log (the figures issue 18 asks for).
    out["lockstep"]["plant_only"] = plant_only_rate(periods, batches)
    interleaved = stub_log_plant_interleaved(2000, 9 if quick else 31)
    out["lockstep"]["stub, stub+log, plant_only interleaved"] = interleaved
    out["lockstep"]["stub+log_vs_plant_only"] = interleaved["stub+log_vs_plant_only"]
    # The same logged session with the log's chunks at lz4 (the default) and uncompressed.
    out["lockstep"]["stub+log, lz4 and uncompressed interleaved"] = log_compression_interleaved(
        2000, 5 if quick else 15)
    out["hil_run_startup"] = hil_run_startup(3 if quick else 7)
    # Two `hil run` side by side, OpenBLAS at hil's one thread and at its own default.
    out["hil_run_side_by_side_openblas"] = startup_side_by_side(2 if quick else 5)
    # TELEMETRY is 8 classic CAN frames, each read a byte at a time by python-can's slcan:
    # the rate a CAN profile gets with telemetry_divider 10 in its controller section.
    try:
        out["lockstep"]["stub-can, TELEMETRY 1 in 10"] = lockstep_rate(
            "stub-can", False, periods // 5, batches, controller={"telemetry_divider": 10})
    except Exception as exc:  # noqa: BLE001
        out["lockstep"]["stub-can, TELEMETRY 1 in 10"] = {"error": str(exc)}
    # The stub's FOC law (control_law 1) answers DUTY: the plant integrates each leg's
    # centre-aligned PWM edges instead of one switch word per period. Beside "stub" (DTC).
    for log in (False, True):
        key = f"stub{'+log' if log else ''}, FOC (DUTY)"
        try:
            out["lockstep"][key] = lockstep_rate("stub", log, periods, batches,
                                                 controller={"control_law": 1, "torque_limit_nm": 2.0})
        except Exception as exc:  # noqa: BLE001
            out["lockstep"][key] = {"error": str(exc)}
    # The protocol's share on a bare pty (bench.protocol), then stub-pty against the bare
    # echo, batches interleaved, with the sessions' default CPU-latency hold and without it.
    try:
        from bench.protocol import pty_round_trips

        out["bare_pty"] = pty_round_trips(2000 if quick else 5000, 3 if quick else 5)
    except Exception as exc:  # noqa: BLE001
        out["bare_pty"] = {"error": str(exc)}
    for hold in (True, False):
        key = "stub_pty_vs_bare_pty" + ("" if hold else "_without_cpu_latency_hold")
        try:
            out[key] = stub_pty_vs_bare(hold, 500 if quick else 2000, 3 if quick else 7)
        except Exception as exc:  # noqa: BLE001
            out[key] = {"error": str(exc)}
    # Real time: 50 us is the paper's period; then the fastest of a ladder that held (no tick
    # more than half a period late, no missing answer, no overrun: realtime.held).
    hold_s = 2.0 if quick else 10.0
    out["realtime_50us"] = realtime_hold(50e-6, 1.0 if quick else 2.0)
    ladder = []
    best = None
    for period_us in (5000, 2000, 1000, 500, 250, 100):
        stats = realtime_hold(period_us * 1e-6, hold_s)
        ladder.append(stats)
        stats["held"] = held(stats)
        if stats["held"]:
            best = stats
        else:
            break
    out["realtime_ladder"] = ladder
    out["realtime_fastest_held"] = best
    return out
