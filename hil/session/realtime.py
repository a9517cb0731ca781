"""The real-time clock: the plant runs on the wall clock, the board on its own.

How the period is kept on a general-purpose OS (measured on a 2-core VM: a bare
Python busy-wait at 50 us is late by more than a period hundreds of times in
10 s, SCHED_FIFO makes it worse through RT throttling):

* deadlines are absolute (t0 + k*T on the monotonic perf counter), so lateness
  never accumulates into drift;
* the loop sleeps until ``spin_s`` before a deadline, then busy-waits to it:
  sleeping alone overshoots by 50-100 us, spinning alone steals the core the
  board process needs;
* while the session lasts, /dev/cpu_dma_latency is held at 0 where permitted (the session's
  hil/session/cpu_latency.py hold; keeps
  the CPU out of deep idle states, which cuts a pseudo-terminal round trip
  roughly in half); where not permitted this is recorded, not fatal;
* no SCHED_FIFO (the kernel's RT throttling stalls it ~50 ms per second).

Timing convention: at tick k the plant is sampled (SAMPLE k goes out) and
integrates [t_k, t_k+1] with the latest GATES that arrived before the tick; the
answer to SAMPLE k therefore acts from t_k+1 on: the one-period computation
delay of a board that updates its PWM at the next period. An answer that
arrives after the next tick is counted late; one that never arrives, missing.
Every statistic is reported as measured; the verdict turns ERROR when deadline
misses exceed the configured budget.
"""
from __future__ import annotations

import time
from typing import Callable

import numpy as np

from protocol.messages import LEGS_ALL, Duty, DutyLegs, Gates, Sample

from hil.session.errors import SessionError


#: Lateness thresholds as fractions of the period, and what each means for a control loop:
#: a tick 10 % late eats into the board's computation time; 50 % late leaves the board half a
#: period for its step (a typical firmware budget); a whole period late is a lost period
#: (a deadline miss: the plant held the previous switches for two periods).
LATENESS_THRESHOLDS = {"late_over_10pct": 0.1, "late_over_50pct": 0.5, "deadline_misses": 1.0}


def lateness_summary(lateness_s: np.ndarray, period_s: float) -> dict:
    if lateness_s.size == 0:
        return {"periods": 0}
    us = lateness_s * 1e6
    out = {
        "periods": int(us.size),
        "lateness_us_p50": float(np.percentile(us, 50)),
        "lateness_us_p99": float(np.percentile(us, 99)),
        "lateness_us_max": float(us.max()),
    }
    for key, fraction in LATENESS_THRESHOLDS.items():
        out[key] = int(np.count_nonzero(lateness_s > fraction * period_s))
    return out


def held(stats: dict) -> bool:
    """The clock held its period: no tick more than half a period late, no answer missing,
    no overrun (a period whose own work took longer than the period)."""
    return (stats.get("periods", 0) > 0 and stats.get("late_over_50pct", 1) == 0
            and stats.get("missing_answers", 1) == 0 and stats.get("overruns", 1) == 0)


def run_realtime(session, count: int, stop: Callable[[], bool] | None = None,
                 spin_s: float = 200e-6) -> int:
    """Runs ``count`` periods of ``session`` against the wall clock."""
    plant = session.plant
    link = session.conn.link
    recorder = session.recorder
    dispatch = session.dispatch
    cfg = session.config
    period_s = cfg.realtime_period_s or session.period_s
    period_ns = round(period_s * 1e9)
    budget = cfg.realtime_miss_budget
    stats = session.rt_stats
    stats.setdefault("period_s", period_s)
    lateness = []
    late_answers = missing = misses = overruns = 0
    # The newest period answered, kept across calls: the watchdog counts from it.
    answered_period = session.rt_answered_period
    if answered_period is None:
        answered_period = plant.period - 1
    watchdog = session.watchdog
    latest_gates = latest_duty = latest_legs = None
    clock = time.perf_counter_ns
    sleep = time.sleep
    sampler = session.sensor_sampler    # a sensor-set board's SAMPLE_SENSORS (SPEC 6.13)
    stats["cpu_dma_latency"] = session.cpu_latency.status
    t0 = clock()
    done = 0
    recording = False
    try:
        for done in range(1, count + 1):
            deadline = t0 + (done - 1) * period_ns
            # Drain answers until the deadline: sleep most of the way, spin the rest.
            while True:
                now = clock()
                msg = link.recv(0.0)
                while msg is not None:
                    t = type(msg)
                    if t is Gates or t is Duty or t is DutyLegs:
                        # an answer to a SAMPLE sent (period < plant.period); a future one is not
                        if answered_period < msg.period < plant.period:
                            answered_period = msg.period
                            if t is Gates:      # (bits 6-7 reserved: ignored, SPEC 4)
                                latest_gates, latest_duty = msg.gates & 0x3F, None
                            else:
                                d = msg.duty
                                latest_gates, latest_duty = None, (d[0] / 65535.0, d[1] / 65535.0,
                                                                   d[2] / 65535.0)
                            # DUTY_LEGS floats the legs whose bit is 0 (reserved bits ignored)
                            latest_legs = msg.leg_enable & LEGS_ALL if t is DutyLegs else None
                            watchdog.answered()
                        else:
                            late_answers += 1
                    else:
                        dispatch(msg)
                    msg = link.recv(0.0)
                remaining = deadline - clock()
                if remaining <= 0:
                    break
                if remaining > spin_s * 1e9:
                    sleep((remaining - spin_s * 1e9) / 1e9)
            tick = clock()
            late_s = (tick - deadline) / 1e9
            lateness.append(late_s)
            if sampler is None:
                sample, msg_out = plant.sample(), None
            else:
                sample, msg_out = sampler()
            k = sample.period
            if late_s > period_s:
                misses += 1
                # in the event list, the log and on the console (hil.run.console, rate-limited)
                session.event("deadline_miss", period=k, late_us=late_s * 1e6)
            if k > 0 and answered_period < k - 1:
                missing += 1
                session.event("missed", period=k - 1)     # no answer to the last SAMPLE by this tick
                why = watchdog.missed()
                if why is not None:
                    plant.safe_state()
                    session.rt_answered_period = answered_period
                    why = session._with_report(why)
                    session.error = (f"watchdog: {why}; at period {k} (t = {k * session.period_s:.6f} s) "
                                     f"on '{session.config.link}'")
                    session.event("watchdog", period=k, reason=why)
                    _store(stats, lateness, period_s, late_answers, missing, overruns)
                    raise SessionError(session.error)
            if msg_out is None:
                msg_out = Sample(k, sample.adc_i1, sample.adc_i2, sample.adc_vdc, sample.encoder,
                                 sample.status)
            link.send(msg_out)
            recording = True    # a failing log (a full disk) is not the link's failure
            recorder.period(k, plant.truth(), sample)
            recording = False
            if latest_duty is None:
                plant.step(latest_gates)
            else:
                plant.step(duty=latest_duty, legs=latest_legs)
            if clock() - tick > period_ns:
                overruns += 1
            if misses > budget:
                plant.safe_state()
                session.error = (f"real-time clock missed {misses} deadlines (budget {budget}) "
                                 f"at {period_s * 1e6:g} us per period")
                _store(stats, lateness, period_s, late_answers, missing, overruns)
                raise SessionError(session.error)
            if stop is not None and stop():
                break
    except OSError as exc:      # LinkError is an OSError: the line is gone (a board that closed it)
        if recording:
            raise
        session.rt_answered_period = answered_period
        _store(stats, lateness, period_s, late_answers, missing, overruns)
        session._link_failed(plant.period, exc)    # safe-states the plant, names the period
    session.rt_answered_period = answered_period
    _store(stats, lateness, period_s, late_answers, missing, overruns)
    return done


def _store(stats: dict, lateness: list[float], period_s: float, late_answers: int, missing: int,
           overruns: int) -> None:
    summary = lateness_summary(np.asarray(lateness), period_s)
    for key in ("periods", *LATENESS_THRESHOLDS):
        stats[key] = stats.get(key, 0) + summary.get(key, 0)
    for key in ("lateness_us_p50", "lateness_us_p99"):
        if key in summary:
            stats[key] = summary[key]
    stats["lateness_us_max"] = max(stats.get("lateness_us_max", 0.0), summary.get("lateness_us_max", 0.0))
    stats["late_answers"] = stats.get("late_answers", 0) + late_answers
    stats["missing_answers"] = stats.get("missing_answers", 0) + missing
    stats["overruns"] = stats.get("overruns", 0) + overruns
