"""Watching it live (issue 17): a WebSocket client speaking the Foxglove SDK's protocol
(subprotocol foxglove.sdk.v1, the JSON/binary ops of Foxglove's ws-protocol) connects to
`hil serve --live`, subscribes to /plant/truth and /ctrl/telemetry, decodes the protobuf
messages with the schemas the server advertises, checks that the speed follows the
reference, publishes a new reference on /cmd and sees the speed follow it."""
from __future__ import annotations

import asyncio
import base64
import json
import os
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
import websockets
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

REPO = Path(__file__).resolve().parents[1]
SUBPROTOCOL = "foxglove.sdk.v1"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def message_class(channel: dict):
    """The protobuf class of an advertised channel, from its FileDescriptorSet."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))


class Viewer:
    def __init__(self, ws):
        self.ws = ws
        self.channels: dict[str, dict] = {}
        self.classes: dict[int, tuple[str, type]] = {}

    async def advertised(self, topics: set[str], timeout_s: float = 10.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not topics <= set(self.channels):
            m = await asyncio.wait_for(self.ws.recv(), max(0.1, deadline - time.monotonic()))
            if isinstance(m, str) and json.loads(m)["op"] == "advertise":
                for c in json.loads(m)["channels"]:
                    self.channels[c["topic"]] = c

    async def subscribe(self, topics: list[str]) -> None:
        subs = []
        for i, topic in enumerate(topics, start=1):
            c = self.channels[topic]
            assert c["encoding"] == "protobuf" and c["schemaEncoding"] == "protobuf"
            self.classes[i] = (topic, message_class(c))
            subs.append({"id": i, "channelId": c["id"]})
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    async def messages(self, seconds: float):
        """(topic, decoded message) for `seconds` of wall time."""
        out = []
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            try:
                m = await asyncio.wait_for(self.ws.recv(), max(0.05, deadline - time.monotonic()))
            except asyncio.TimeoutError:
                break
            if isinstance(m, bytes) and m[0] == 0x01:          # message data
                sub_id, _log_time = struct.unpack_from("<IQ", m, 1)
                topic, cls = self.classes[sub_id]
                out.append((topic, cls.FromString(m[13:])))
        return out

    async def until_simulated(self, t_end_s: float, wall_s: float = 30.0):
        """(topic, decoded message) until a /plant/truth row at simulated time t_end_s: windows
        in simulated time, whatever the rate the run reaches on a loaded machine."""
        out = []
        reached = -1.0
        deadline = time.monotonic() + wall_s
        while reached < t_end_s:
            assert time.monotonic() < deadline, f"simulated time never reached {t_end_s} s"
            got = await self.messages(0.2)
            out += got
            reached = max([reached] + [m.t_s for t, m in got if t == "/plant/truth"])
        return out

    async def publish_command(self, command: dict) -> None:
        await self.ws.send(json.dumps({"op": "advertise", "channels": [
            {"id": 1, "topic": "/cmd", "encoding": "json", "schemaName": "hil.cmd"}]}))
        await asyncio.sleep(0.2)
        await self.ws.send(b"\x01" + struct.pack("<I", 1) + json.dumps(command).encode())


def test_a_viewer_sees_the_speed_follow_the_reference_and_changes_it(tmp_path):
    port = free_port()
    token = "test-token-of-this-run"           # HIL_LIVE_TOKEN: a scripted viewer's fixed token
    serve = subprocess.Popen([sys.executable, "-m", "hil.cli.main", "serve", "--link", "stub",
                              "--enable", "--speed-rpm", "1500", "--modbus", "off",
                              "--duration", "12", "--pace", "realtime",
                              "--live", f"127.0.0.1:{port}"],
                             cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env={**os.environ, "HIL_LIVE_TOKEN": token})
    try:
        async def session():
            deadline = time.monotonic() + 20
            while True:
                try:
                    ws = await websockets.connect(f"ws://127.0.0.1:{port}/?token={token}",
                                                  subprotocols=[SUBPROTOCOL])
                    break
                except OSError:
                    if time.monotonic() > deadline:
                        raise
                    await asyncio.sleep(0.2)
            async with ws:
                viewer = Viewer(ws)
                await viewer.advertised({"/plant/truth", "/ctrl/telemetry", "/plant/sensors"})
                assert viewer.channels["/plant/truth"]["schemaName"] == "hil.PlantTruth"
                await viewer.subscribe(["/plant/truth", "/ctrl/telemetry"])
                # Windows in simulated time (the rows' t_s), not wall time: on a loaded machine
                # the run may fall behind real time, which must not change the verdict.
                got = await viewer.until_simulated(1.5)              # reach 1500 rpm
                truth = [m for t, m in got if t == "/plant/truth" and m.t_s >= 1.0]
                telemetry = [m for t, m in got if t == "/ctrl/telemetry"]
                # 1 kHz of simulated time: every row 1 ms after the one before (the server
                # drops rows a slow client cannot take, never reorders them)
                steps_ms = {round((b.t_s - a.t_s) * 1e3, 6) for a, b in zip(truth, truth[1:])}
                assert truth and telemetry and all(x >= 1 and x == int(x) for x in steps_ms)
                assert abs(sum(m.speed_rpm for m in truth) / len(truth) - 1500) < 30
                published_at = truth[-1].t_s
                await viewer.publish_command({"speed_ref_rpm": 2500})
                got = await viewer.until_simulated(published_at + 2.0)
                speeds = [m.speed_rpm for t, m in got
                          if t == "/plant/truth" and m.t_s >= published_at + 1.5]
                assert speeds and abs(sum(speeds) / len(speeds) - 2500) < 50
                # the viewer lets it run as fast as it can (how fast depends on the machine:
                # the pacing itself is test_the_pace_a_viewer_chooses_is_kept below)
                await viewer.publish_command({"pace": "fast"})
                await viewer.messages(0.5)
        asyncio.run(asyncio.wait_for(session(), 60))
    finally:
        serve.terminate()
        out, err = serve.communicate(timeout=20)
    assert f"live (Foxglove) on ws://127.0.0.1:{port}/?token={token}" in err
    assert "hil serve: live:" not in err          # every /cmd message was taken


def test_the_pace_a_viewer_chooses_is_kept():
    from hil.cli.serve import Pacer

    pacer = Pacer("realtime", 50e-6)
    assert pacer.wait_s(0, 100.0) == 0.0                  # pacing starts here
    assert pacer.wait_s(200, 100.002) == pytest.approx(0.008)   # 10 ms simulated in 2 ms
    assert pacer.wait_s(400, 100.030) == 0.0              # behind the clock: no sleep
    pacer.mode = "fast"
    assert pacer.wait_s(10_000, 100.031) == 0.0           # fast never sleeps
    pacer.mode = "realtime"                               # counted from the switch back
    assert pacer.wait_s(10_000, 100.040) == 0.0
    assert pacer.wait_s(10_200, 100.041) == pytest.approx(0.009)


def test_viewer_parameters_go_through_the_modbus_mailbox_and_bad_ones_are_refused_by_name():
    from hil.live.stream import LiveStream
    from hil.ports.modbus import ControlMailbox

    stream = LiveStream("127.0.0.1", 0, period_s=50e-6)
    try:
        stream._command(b'{"speed_ref_rpm": 100}')          # no mailbox: a plan's run
        assert "takes no parameters from viewers" in stream.take_errors()[0]
        mailbox = ControlMailbox(speed_ref_rpm=1500, run=True)
        stream.attach_mailbox(mailbox)
        stream._command(b'{"speed_ref_rmp": 100}')
        stream._command(b"[1, 2]")
        stream._command(b'{"load_torque_nm": "a lot"}')
        stream._command(b'{"pace": "slow"}')
        stream._command(b'{"speed_ref_rpm": 2500, "enable": false, "load_torque_nm": 0.5}')
        stream._command(b'{"pace": "realtime"}')
        errors = stream.take_errors()
        assert "unknown key 'speed_ref_rmp'" in errors[0]
        assert "expected a JSON object" in errors[1]
        assert "'load_torque_nm': expected a number" in errors[2]
        assert "'pace': expected one of fast, realtime" in errors[3]
        assert len(errors) == 4 and stream.commands_taken == 2 and stream.pace == "realtime"
        # what a Modbus client reading the holding registers would now see, and what the
        # session takes between two periods
        commanded = mailbox.commanded()
        assert (commanded.speed_ref_rpm, commanded.run, commanded.load_torque_nm) == (2500, False, 0.5)
        taken = mailbox.take_requests()
        assert (taken.speed_ref_rpm, taken.run, taken.load_torque_nm, taken.fault_bits) == \
            (2500, False, 0.5, None)
    finally:
        stream.close()


def test_viewer_values_that_are_not_finite_or_of_the_wrong_kind_are_refused_by_name():
    """JSON lets a viewer send NaN, Infinity and null where a number is due, and 1.5 where a
    bit mask is: none of them may reach the mailbox (a NaN speed reference would be written
    to the board, a null 'enable' would read as false)."""
    from hil.live.stream import LiveStream
    from hil.ports.modbus import ControlMailbox

    stream = LiveStream("127.0.0.1", 0, period_s=50e-6)
    try:
        mailbox = ControlMailbox(speed_ref_rpm=1500, run=True)
        stream.attach_mailbox(mailbox)
        for bad in (b'{"speed_ref_rpm": NaN}', b'{"load_torque_nm": Infinity}',
                    b'{"speed_ref_rpm": -Infinity}', b'{"enable": null}', b'{"enable": 2}',
                    b'{"fault_bits": 1.5}', b'{"fault_bits": true}', b'{"speed_ref_rpm": true}'):
            stream._command(bad)
        errors = stream.take_errors()
        assert len(errors) == 8 and stream.commands_taken == 0, errors
        for error, key in zip(errors, ("speed_ref_rpm", "load_torque_nm", "speed_ref_rpm", "enable",
                                       "enable", "fault_bits", "fault_bits", "speed_ref_rpm")):
            assert f"'{key}'" in error
        assert mailbox.take_requests() is None                     # nothing was requested
        stream._command(b'{"speed_ref_rpm": 2000, "enable": true, "fault_bits": 3}')
        assert stream.take_errors() == [] and stream.commands_taken == 1
    finally:
        stream.close()


def test_hil_run_hands_every_nth_period_to_the_live_stream():
    """`hil run --live` gives the runner a LiveStream; the recorder hands it every `every`-th
    period's truth and telemetry (here a stand-in that counts, 1 kHz at 50 us = every 20th)."""
    from hil.plans.format import load_plan
    from hil.run.runner import run_plan

    class Counting:
        every = 20

        def __init__(self):
            self.periods, self.telemetry = [], []

        def follow(self, period_s):
            return self

        def period(self, k, truth, sample):
            self.periods.append(k)

        def telemetry_row(self, row):
            self.telemetry.append(row[0])

    sink = Counting()
    plan = load_plan(REPO / "test_plans" / "01_speed_step_sensored.yaml")
    result, _ = run_plan(plan, live=sink)
    assert result.outcome.value == "PASS"
    n = round(result.sim_duration_s / 50e-6)
    assert sink.periods and all(k % 20 == 0 for k in sink.periods)
    assert abs(len(sink.periods) - n / 20) <= 2
    assert set(sink.telemetry) <= set(sink.periods) and len(sink.telemetry) >= len(sink.periods) - 2


def test_rows_reach_the_server_in_batches_and_only_for_subscribed_channels():
    """What keeps a viewer's cost off the period loop (python -m bench live measures it): the
    stream hands rows to the server FLUSH_ROWS at a time, so one wake of the server's thread
    carries a batch, and packs nothing for a channel no viewer subscribes to. Counted with the
    channels' log calls stood in for; a stream that logged row by row, or logged to channels
    nobody watches, fails here."""
    from types import SimpleNamespace

    from hil.live.stream import FLUSH_ROWS, LiveStream

    stream = LiveStream("127.0.0.1", 0, period_s=50e-6)
    calls: list[tuple[str, int]] = []
    batches_seen: list[int] = []
    try:
        for topic in (stream.truth, stream.sensors, stream.telemetry):
            topic.log = lambda t_ns, values, name=topic.channel.topic(): calls.append((name, t_ns))
        sample = SimpleNamespace(adc_i1=1, adc_i2=2, adc_vdc=3, encoder=4, status=0)
        truth = tuple(0.0 for _ in range(len(stream.truth._args) // 2))

        def hand_over(rows: int, first: int) -> None:
            for k in range(first, first + rows):
                stream.period(k * stream.every, truth, sample)
                stream.telemetry_row((k * stream.every,) + (0,) * 3 + (0.0,) * 8)
                batches_seen.append(len(calls))

        hand_over(2 * FLUSH_ROWS, 0)
        assert calls == [] and stream.flushes == 0          # nobody subscribed: nothing packed

        async def watch_and_hand_over():
            async with websockets.connect(stream.url, subprotocols=[SUBPROTOCOL]) as ws:
                viewer = Viewer(ws)
                await viewer.advertised({"/plant/truth", "/ctrl/telemetry", "/plant/sensors"})
                await viewer.subscribe(["/plant/truth"])
                deadline = time.monotonic() + 10
                while not stream.truth.channel.has_sinks():
                    assert time.monotonic() < deadline, "the subscription never arrived"
                    await asyncio.sleep(0.02)
                batches_seen.clear()
                hand_over(2 * FLUSH_ROWS, 1000)

        asyncio.run(asyncio.wait_for(watch_and_hand_over(), 30))
        # Only /plant/truth is watched: its rows, in two batches of FLUSH_ROWS, in order.
        assert {name for name, _ in calls} == {"/plant/truth"}
        assert len(calls) == 2 * FLUSH_ROWS and stream.flushes == 2
        assert [t for _, t in calls] == sorted(t for _, t in calls)
        assert sorted(set(batches_seen)) == [0, FLUSH_ROWS, 2 * FLUSH_ROWS]   # whole batches only
    finally:
        stream.close()
