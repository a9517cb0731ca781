"""Modbus control port figures (docs/modbus.md).

``mailbox_ns``: what the session pays per call of the shared-memory ControlMailbox, median
over batches (each batch times `calls` calls and divides): `pending` and `take_requests()`
with nothing pending (every period), `publish(PlantSnapshot(...))` with the snapshot built
(every N periods) and `take_requests()` right after a port-side write (only when a client
wrote; a batch of write + take minus a batch of writes alone).

``request_ms``: one Modbus TCP request through pymodbus over loopback, round trip as a
synchronous client in this process sees it (server in a thread), median of `requests`.

``period_gaps``: a lockstep session over the in-process stub (`--link stub`, no log) runs
for `seconds` of wall time and stamps every period's end (perf_counter_ns in the session's
`on_period` hook). A client in another process reads the 16 input registers and writes
holding register 0 every 10 ms for the whole run. The same run is made with no port at all
(what the machine's background does to a period), with the port's server in a thread of
the session's process (`isolation="thread"`, what `hil run --modbus` and `hil serve` use in
lockstep) and in a process of its own (`isolation="process"`, what `hil serve` uses in
real time). Reported per variant: periods/s, median period, periods longer than 100 us and
300 us, the longest, the requests the client completed and their round trip as the client
saw it (median, longest). The three variants run
interleaved `rounds` times; each round is listed and the median over rounds given.
"""
from __future__ import annotations

import multiprocessing
import statistics
import time


def _batches(fn, calls: int, batches: int) -> list[float]:
    out = []
    for _ in range(batches):
        t0 = time.perf_counter_ns()
        fn(calls)
        out.append((time.perf_counter_ns() - t0) / calls)
    return out


def mailbox_costs(calls: int = 20_000, batches: int = 15) -> dict:
    from hil.ports.modbus import ControlMailbox, PlantSnapshot, StateBit

    mb = ControlMailbox(dc_link_voltage_v=70.0)

    def pending(n):
        for _ in range(n):
            mb.pending

    def take_nothing(n):
        take = mb.take_requests
        for _ in range(n):
            take()

    def publish(n):
        pub = mb.publish
        for i in range(n):
            pub(PlantSnapshot(1500.0, 1.0, -0.5, -0.5, 0.8, 70.0, i, 0, state=StateBit.RUNNING,
                              load_torque_nm=0.5))

    def write_only(n):
        req = mb.request
        for i in range(n):
            req(load_torque_nm=0.001 * (i & 1))

    def write_take(n):
        req, take = mb.request, mb.take_requests
        for i in range(n):
            req(load_torque_nm=0.001 * (i & 1))
            take()

    out = {}
    for name, fn in (("pending", pending), ("take_requests_nothing_pending", take_nothing),
                     ("publish_with_snapshot_built", publish)):
        out[name] = round(statistics.median(_batches(fn, calls, batches)), 1)
    # write and write + take batches alternate, paired medians
    diffs = []
    for _ in range(batches):
        w = _batches(write_only, calls // 4, 1)[0]
        wt = _batches(write_take, calls // 4, 1)[0]
        diffs.append(wt - w)
    out["take_requests_after_a_write"] = round(statistics.median(diffs), 1)
    out["calls_per_batch"] = calls
    out["batches"] = batches
    return out


def request_latency(requests: int = 300) -> dict:
    from pymodbus.client import ModbusTcpClient

    from hil.ports.modbus import ControlMailbox, ModbusPort

    mb = ControlMailbox(dc_link_voltage_v=70.0)
    with ModbusPort(mb, port=0, isolation="thread") as port:
        host, number = port.tcp_address
        client = ModbusTcpClient(host, port=number)
        client.connect()
        try:
            reads, writes = [], []
            for i in range(requests):
                t0 = time.perf_counter_ns()
                client.read_input_registers(0, count=16)
                t1 = time.perf_counter_ns()
                client.write_register(0, i & 0xFF)
                t2 = time.perf_counter_ns()
                reads.append((t1 - t0) / 1e6)
                writes.append((t2 - t1) / 1e6)
        finally:
            client.close()
    return {"read_16_input_registers_ms": round(statistics.median(reads), 3),
            "write_1_holding_register_ms": round(statistics.median(writes), 3),
            "requests_each": requests}


def _client_main(host: str, port: int, interval_s: float, go, stop, counts) -> None:
    """In another process: read 16 input registers and write holding register 0 every
    interval_s until told to stop; counts = requests completed, median and longest round
    trip in ns (as this client sees it)."""
    from pymodbus.client import ModbusTcpClient

    client = ModbusTcpClient(host, port=port)
    client.connect()
    go.wait()
    done = 0
    latencies = []
    nxt = time.monotonic()
    while not stop.is_set():
        t0 = time.perf_counter_ns()
        client.read_input_registers(0, count=16)
        t1 = time.perf_counter_ns()
        client.write_register(0, done & 0xFF)
        latencies += [t1 - t0, time.perf_counter_ns() - t1]
        done += 2
        nxt += interval_s
        delay = nxt - time.monotonic()
        if delay > 0:
            stop.wait(delay)
    latencies.sort()
    counts[0] = done
    counts[1] = latencies[len(latencies) // 2] if latencies else 0
    counts[2] = latencies[-1] if latencies else 0
    client.close()


def _session_gaps(isolation: str | None, seconds: float, interval_s: float = 0.01) -> dict:
    from hil.ports.modbus import ControlMailbox, ModbusPort
    from hil.session.bench_session import BenchSession, SessionConfig
    from plant_rt import load_profile

    stamps: list[int] = []
    stamp = stamps.append
    clock = time.perf_counter_ns
    profile = load_profile()
    ctx = multiprocessing.get_context("spawn")
    mailbox = ControlMailbox(load_torque_nm=0.0, dc_link_voltage_v=70.0, run=True)
    port = client = None
    go, stop, counts = ctx.Event(), ctx.Event(), ctx.Array("q", 3)
    with BenchSession(profile, SessionConfig(link="stub"), on_period=lambda k: stamp(clock())) as s:
        s.attach_mailbox(mailbox)
        s.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        if isolation is not None:
            port = ModbusPort(mailbox, port=0, isolation=isolation, load_torque_limit_nm=2.0).start()
            client = ctx.Process(target=_client_main, args=(*port.tcp_address, interval_s, go, stop, counts),
                                 daemon=True)
            client.start()
        try:
            s.run_periods(4000)                  # warm up: past the start of the speed ramp
            stamps.clear()
            go.set()
            t_end = time.monotonic() + seconds
            while time.monotonic() < t_end:
                s.run_periods(2000)
            stop.set()
            if client is not None:
                client.join(10)
        finally:
            if port is not None:
                port.stop()
    d = [(b - a) / 1e3 for a, b in zip(stamps, stamps[1:])]
    span_s = (stamps[-1] - stamps[0]) / 1e9
    return {"periods": len(d), "periods_per_s": round(len(d) / span_s),
            "median_period_us": round(statistics.median(d), 1),
            "periods_over_100us": sum(x > 100 for x in d), "periods_over_300us": sum(x > 300 for x in d),
            "longest_us": round(max(d)), "client_requests": int(counts[0]) if isolation else 0,
            "client_round_trip_median_ms": round(counts[1] / 1e6, 3) if isolation else None,
            "client_round_trip_longest_ms": round(counts[2] / 1e6, 1) if isolation else None}


def period_gaps(seconds: float = 2.5, rounds: int = 3) -> dict:
    variants = (("no_port", None), ("thread", "thread"), ("process", "process"))
    runs: dict[str, list[dict]] = {name: [] for name, _ in variants}
    for _ in range(rounds):
        for name, isolation in variants:
            runs[name].append(_session_gaps(isolation, seconds))
    out: dict = {"seconds_per_run": seconds, "rounds": rounds, "client": "16 input registers read + "
                 "holding register 0 written every 10 ms, from another process"}
    for name, rs in runs.items():
        med = {k: (statistics.median(r[k] for r in rs) if rs[0][k] is not None else None) for k in rs[0]}
        out[name] = {"median_over_rounds": med, "rounds": rs}
    return out


def run(quick: bool = False) -> dict:
    return {"mailbox_ns": mailbox_costs(calls=5_000 if quick else 20_000, batches=7 if quick else 15),
            "request_ms": request_latency(100 if quick else 300),
            "period_gaps": period_gaps(seconds=1.5 if quick else 2.5, rounds=1 if quick else 3)}


if __name__ == "__main__":
    import json

    print(json.dumps(run(quick=True), indent=2))
