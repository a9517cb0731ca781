"""Who may drive the bench from a browser (docs/live.md): the live view's gate refuses a
WebSocket upgrade without the run's token or from an Origin not on the allow-list, and /cmd
is applied only from connections it let through. Real WebSocket clients on 127.0.0.1."""
from __future__ import annotations

import asyncio
import json
import struct

import pytest
import websockets
from websockets.exceptions import InvalidStatus

from hil.live.stream import LiveStream
from hil.ports.modbus import ControlMailbox

SUBPROTOCOL = "foxglove.sdk.v1"


@pytest.fixture
def stream():
    stream = LiveStream("127.0.0.1", 0, period_s=50e-6, token="t0ken-of-the-run",
                        origins=("https://app.foxglove.dev", "http://lab.example:8080"))
    stream.attach_mailbox(ControlMailbox(speed_ref_rpm=0.0))
    try:
        yield stream
    finally:
        stream.close()


async def _publish(url: str, origin: str | None, command: dict) -> str:
    """Connects, advertises /cmd, publishes `command`; the first op the server sent."""
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL], origin=origin,
                                  open_timeout=10) as ws:
        first = json.loads(await asyncio.wait_for(ws.recv(), 10))["op"]
        await ws.send(json.dumps({"op": "advertise", "channels": [
            {"id": 1, "topic": "/cmd", "encoding": "json", "schemaName": "hil.cmd"}]}))
        await ws.send(b"\x01" + struct.pack("<I", 1) + json.dumps(command).encode())
        await asyncio.sleep(0.3)            # the server hands it to the listener meanwhile
    return first


def _refused(url: str, origin: str | None) -> int:
    async def attempt():
        with pytest.raises(InvalidStatus) as info:
            await _publish(url, origin, {"speed_ref_rpm": 100})
        return info.value.response.status_code
    return asyncio.run(asyncio.wait_for(attempt(), 30))


def _wait_for_command(stream, taken: int) -> None:
    """/cmd reaches the listener on the SDK's thread: wait (bounded) until it counted."""
    async def wait():
        while stream.commands_taken + stream.commands_refused < taken:
            await asyncio.sleep(0.02)
    asyncio.run(asyncio.wait_for(wait(), 10))


def test_a_page_from_another_origin_is_refused_even_with_the_token(stream):
    assert _refused(stream.url, "http://evil.example") == 403
    assert stream.commands_taken == 0 and stream._mailbox.take_requests() is None
    errors = stream.take_errors()
    assert len(errors) == 1 and "Origin 'http://evil.example' is not on the allow-list" in errors[0]
    assert stream.gate.refused == 1


def test_without_the_token_or_with_a_wrong_one_the_upgrade_is_refused(stream):
    base = f"ws://127.0.0.1:{stream.port}"
    assert _refused(base, None) == 403
    assert _refused(f"{base}/?token=guess", "https://app.foxglove.dev") == 403
    assert _refused(f"{base}/?token={stream.token}x", None) == 403
    errors = stream.take_errors()
    assert ["no token" in errors[0], "wrong token" in errors[1], "wrong token" in errors[2]] == \
        [True, True, True], errors
    assert stream.commands_taken == 0 and stream._mailbox.take_requests() is None


def test_the_foxglove_app_and_configured_origins_with_the_token_drive_the_bench(stream):
    for origin, rpm in (("https://app.foxglove.dev", 1200), ("http://lab.example:8080", 900),
                        (None, 600)):                        # None: a script, not a page
        first = asyncio.run(asyncio.wait_for(_publish(stream.url, origin, {"speed_ref_rpm": rpm}), 30))
        assert first == "serverInfo"
    _wait_for_command(stream, 3)
    assert stream.commands_taken == 3 and stream.take_errors() == []
    assert stream._mailbox.take_requests().speed_ref_rpm == 600


def test_cmd_sent_past_the_gate_to_the_sdk_port_is_not_applied(stream):
    """A page that found the SDK's own (ephemeral) port connects there: it may watch, but the
    listener applies /cmd only from connections the gate opened."""
    inner = f"ws://127.0.0.1:{stream.server.port}"
    asyncio.run(asyncio.wait_for(_publish(inner, "http://evil.example", {"speed_ref_rpm": 1}), 30))
    _wait_for_command(stream, 1)
    assert stream.commands_taken == 0 and stream._mailbox.take_requests() is None
    assert "did not come through the gate" in stream.take_errors()[0]


def test_hil_serve_refuses_the_values_that_killed_it_by_name_and_runs_on(tmp_path):
    """`hil serve` died on {"speed_ref_rpm": 1e308} (float32 overflow) and on
    {"load_torque_nm": 1e308} (a NaN plant); fault bits -1 injected every fault. Now each is
    refused on the console with its range, the good command after them is applied, and the
    run ends by its --duration with exit status 0."""
    import os
    import socket
    import subprocess
    import sys
    import time
    from pathlib import Path

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    token = "serve-test-token"
    serve = subprocess.Popen([sys.executable, "-m", "hil.cli.main", "serve", "--link", "stub",
                              "--enable", "--speed-rpm", "1000", "--modbus", "off",
                              "--duration", "4", "--pace", "realtime", "--live", f"127.0.0.1:{port}",
                              "--log", str(tmp_path / "serve.mcap")],
                             cwd=Path(__file__).resolve().parents[1], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True,
                             env={**os.environ, "HIL_LIVE_TOKEN": token})
    try:
        async def drive():
            url = f"ws://127.0.0.1:{port}/?token={token}"
            deadline = time.monotonic() + 20
            while True:
                try:
                    ws = await websockets.connect(url, subprotocols=[SUBPROTOCOL], open_timeout=10)
                    break
                except OSError:
                    assert time.monotonic() < deadline, "hil serve --live never listened"
                    await asyncio.sleep(0.2)
            async with ws:
                await asyncio.wait_for(ws.recv(), 10)                     # serverInfo
                await ws.send(json.dumps({"op": "advertise", "channels": [
                    {"id": 1, "topic": "/cmd", "encoding": "json", "schemaName": "hil.cmd"}]}))
                for command in ({"speed_ref_rpm": 1e308}, {"load_torque_nm": 1e308},
                                {"fault_bits": -1}, {"fault_bits": 2**64 + 4},
                                {"speed_ref_rpm": 1500}):
                    await ws.send(b"\x01" + struct.pack("<I", 1) + json.dumps(command).encode())
                await asyncio.sleep(0.5)
        asyncio.run(asyncio.wait_for(drive(), 40))
        out, err = serve.communicate(timeout=60)
    finally:
        if serve.poll() is None:
            serve.kill()
            serve.communicate()
    assert serve.returncode == 0, err
    assert "hil serve: live: /cmd: 'speed_ref_rpm': outside -6000 .. 6000 (2 x the motor's rated" in err
    assert "hil serve: live: /cmd: 'load_torque_nm': outside -10.44 .. 10.44" in err
    assert "hil serve: live: /cmd: 'fault_bits': fault bits are >= 0" in err
    assert "hil serve: live: /cmd: 'fault_bits': bits 0x10000000000000000 name no fault" in err
    assert err.count("hil serve: live:") == 4, err
    assert "periods (4.000 s simulated)" in err
    from hil.logs.reader import read_log

    events = read_log(tmp_path / "serve.mcap")["/plan/events"]
    speeds = [v for k, v in zip(events["kind"], events["speed_ref_rpm"]) if k == "command"]
    assert speeds[-1] == 1500.0                  # the good command after the refused ones
