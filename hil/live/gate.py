"""Who may open the live view: a front door before the Foxglove server (docs/live.md).

foxglove-sdk's WebSocket server (0.30) accepts every upgrade: it neither checks the Origin
header nor asks for a token, so any web page the user has open could connect to 127.0.0.1
and publish on /cmd. This gate owns the address the user asked for and lets an upgrade
through to the SDK's server (on an ephemeral loopback port) only when

* the request names the run's token: ``ws://HOST:PORT/?token=TOKEN`` (the URL `--live`
  prints; compared in constant time), and
* its Origin header, when it has one, is on the allow-list (Foxglove's app by default).
  Browsers always send Origin on a WebSocket upgrade; a client without one is not a web
  page (a script, a tool) and needs the token alone.

Anything else gets ``403 Forbidden`` naming why, is counted and reported (``on_refusal``).
Past the upgrade the gate copies bytes both ways without looking at them (no per-message
work; the WebSocket frames pass as they are).

A web page that found the SDK's own port could still connect there; so that it cannot
command, the gate opens each connection it lets through by advertising the secret topic
``auth_topic`` on the client's behalf (one masked WebSocket frame): the stream applies /cmd
only from connections that did (hil.live.stream).
"""
from __future__ import annotations

import asyncio
import hmac
import json
import os
import select
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence
from urllib.parse import parse_qs, urlsplit

#: Foxglove's web app; `hil serve --live-origin ORIGIN` (repeatable) adds others.
FOXGLOVE_ORIGINS = ("https://app.foxglove.dev", "https://studio.foxglove.dev")
#: The client channel id the gate's advertisement uses (clients count theirs up from 0 or 1).
AUTH_CHANNEL_ID = 0xFFFFFFFF
HEAD_LIMIT = 16 * 1024          # an HTTP upgrade request is a few hundred bytes
HEAD_TIMEOUT_S = 5.0            # a client that sends no request in time is dropped


def masked_text_frame(text: str) -> bytes:
    """One final WebSocket text frame from a client (RFC 6455 5.2: clients mask)."""
    payload = text.encode()
    n = len(payload)
    head = bytes([0x81])
    if n < 126:
        head += bytes([0x80 | n])
    elif n < 1 << 16:
        head += bytes([0x80 | 126]) + n.to_bytes(2, "big")
    else:
        head += bytes([0x80 | 127]) + n.to_bytes(8, "big")
    key = os.urandom(4)
    return head + key + bytes(b ^ key[i & 3] for i, b in enumerate(payload))


def _response(status: str, text: str) -> bytes:
    body = (text + "\n").encode()
    return (f"HTTP/1.1 {status}\r\nContent-Type: text/plain; charset=utf-8\r\n"
            f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n").encode() + body


def parse_request_head(head: bytes) -> tuple[str, str, dict[str, str]]:
    """(method, target, headers with lower-case names) of an HTTP/1.1 request head."""
    lines = head.decode("latin-1").split("\r\n")
    parts = lines[0].split(" ")
    if len(parts) != 3:
        raise ValueError("not an HTTP request")
    headers: dict[str, str] = {}
    for line in lines[1:]:
        if not line:
            continue
        name, sep, value = line.partition(":")
        if not sep:
            raise ValueError("malformed header line")
        headers[name.strip().lower()] = value.strip()
    return parts[0], parts[1], headers


class LiveGate:
    """Listens on (host, port), checks each upgrade (module doc) and joins the ones it lets
    through to the Foxglove server on 127.0.0.1:inner_port. Runs as a process of its own
    (``python -m hil.live.gate``, its settings on stdin, never on its command line where
    other users could read the token): copying a viewer's bytes in the bench's process
    would take the GIL from the period loop. Its reports come back as lines on its stdout:
    ``poll()`` hands refusals to ``on_refusal`` and counts them (``refused``); ``stop()``
    closes its stdin, which ends it (as does the bench's death)."""

    def __init__(self, host: str, port: int, inner_port: int, token: str,
                 origins: Sequence[str] = FOXGLOVE_ORIGINS, auth_topic: str = "",
                 on_refusal: Callable[[str], None] | None = None, start_timeout_s: float = 20.0):
        self.host = host
        self.on_refusal = on_refusal
        self.refused = 0
        self.admitted = 0
        self._pending = b""
        config = {"host": host, "port": port, "inner_port": inner_port, "token": token,
                  "origins": [o.rstrip("/") for o in origins], "auth_topic": auth_topic}
        root = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            [root] + ([os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else [])))
        self._process = subprocess.Popen([sys.executable, "-m", "hil.live.gate"],
                                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        try:
            self._process.stdin.write(json.dumps(config).encode() + b"\n")
            self._process.stdin.flush()
            line = self._first_line(start_timeout_s)
        except BaseException:
            self.stop()
            raise
        kind, _, value = line.decode(errors="replace").strip().partition(" ")
        if kind != "ready":
            self.stop()
            raise OSError(f"live: cannot listen on {host}:{port}: "
                          f"{value or 'the gate did not start within %g s' % start_timeout_s}")
        self.port = int(value)

    def _first_line(self, timeout_s: float) -> bytes:
        """The gate's first report (unbuffered reads: later lines stay for poll())."""
        fd = self._process.stdout.fileno()
        os.set_blocking(fd, False)
        deadline = time.monotonic() + timeout_s
        while b"\n" not in self._pending:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                return b""
            data = os.read(fd, 4096)
            if not data:
                return b""
            self._pending += data
        line, _, self._pending = self._pending.partition(b"\n")
        return line

    def poll(self) -> None:
        """Takes the gate's reports so far (never waits)."""
        if self._process is None:
            return
        try:
            data = os.read(self._process.stdout.fileno(), 65536)
        except (BlockingIOError, OSError):
            return
        lines = (self._pending + data).split(b"\n")
        self._pending = lines.pop()
        for line in lines:
            kind, _, value = line.decode(errors="replace").partition(" ")
            if kind == "refused":
                self.refused += 1
                if self.on_refusal is not None:
                    self.on_refusal(value)
            elif kind == "admitted":
                self.admitted += 1

    def stop(self, timeout_s: float = 5.0) -> None:
        """Ends the gate's process (and every connection through it). Idempotent."""
        process = self._process
        if process is None:
            return
        self.poll()
        try:
            process.stdin.close()
        except OSError:
            pass
        try:
            process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout_s)
        process.stdout.close()
        self._process = None


@dataclass(frozen=True)
class _GateConfig:
    """The gate's settings, as its process reads them from stdin."""

    host: str
    port: int
    inner_port: int
    token: str
    origins: tuple[str, ...]
    auth_frame: bytes               # the masked advertisement of the secret topic


def refusal(config: _GateConfig, method: str, target: str, headers: dict[str, str]) -> str | None:
    """Why this upgrade request is refused, or None to let it through."""
    if method != "GET" or headers.get("upgrade", "").lower() != "websocket":
        return "not a WebSocket upgrade"
    origin = headers.get("origin")
    if origin is not None and origin.rstrip("/") not in config.origins:
        return (f"Origin {origin!r} is not on the allow-list ({', '.join(config.origins)}; "
                f"hil serve --live-origin adds one)")
    given = parse_qs(urlsplit(target).query).get("token", [""])[0]
    if not hmac.compare_digest(given.encode(), config.token.encode()):
        return ("no token" if not given else "wrong token") + \
            " (open the URL --live prints: ws://HOST:PORT/?token=...)"
    return None


def _gate_main() -> None:
    """The gate's process: settings from the first line of stdin; serves until stdin closes
    (the bench stopped it, or died)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)      # Ctrl-C is the parent's to handle
    raw = json.loads(sys.stdin.buffer.readline())
    frame = masked_text_frame(json.dumps({"op": "advertise", "channels": [
        {"id": AUTH_CHANNEL_ID, "topic": raw["auth_topic"], "encoding": "json",
         "schemaName": ""}]}))
    config = _GateConfig(raw["host"], int(raw["port"]), int(raw["inner_port"]), raw["token"],
                         tuple(raw["origins"]), frame)
    out = sys.stdout

    def report(kind: str, value: str = "") -> None:
        out.write(f"{kind} {value.replace(chr(10), ' ')}\n")
        out.flush()

    async def main() -> None:
        loop = asyncio.get_running_loop()
        stop = asyncio.Event()
        tasks: set[asyncio.Task] = set()

        async def handle(reader, writer) -> None:
            task = asyncio.current_task()
            tasks.add(task)
            try:
                await _connection(config, reader, writer, report)
            finally:
                tasks.discard(task)

        try:
            server = await asyncio.start_server(handle, config.host, config.port, limit=HEAD_LIMIT)
        except OSError as exc:
            report("error", str(exc))
            return

        def on_parent() -> None:
            if not os.read(sys.stdin.fileno(), 4096):       # EOF: stop, or the parent died
                loop.remove_reader(sys.stdin.fileno())
                stop.set()

        loop.add_reader(sys.stdin.fileno(), on_parent)
        report("ready", str(server.sockets[0].getsockname()[1]))
        await stop.wait()
        server.close()
        for task in list(tasks):
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)

    asyncio.run(main())


async def _connection(config: _GateConfig, reader, writer, report) -> None:
    peer = writer.get_extra_info("peername")
    try:
        try:
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), HEAD_TIMEOUT_S)
            method, target, headers = parse_request_head(head)
            why = refusal(config, method, target, headers)
        except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, asyncio.TimeoutError,
                ValueError, ConnectionError):
            why, head = "no valid HTTP request", b""
        if why is not None:
            report("refused", f"refused a connection from {peer[0] if peer else '?'}: {why}")
            writer.write(_response("403 Forbidden", f"hil live: {why}"))
            await writer.drain()
            return
        inner_reader, inner_writer = await asyncio.open_connection("127.0.0.1", config.inner_port)
        try:
            inner_writer.write(head)
            await inner_writer.drain()
            answer = await asyncio.wait_for(inner_reader.readuntil(b"\r\n\r\n"), HEAD_TIMEOUT_S)
            writer.write(answer)
            await writer.drain()
            if answer.split(b" ", 2)[1:2] != [b"101"]:
                return
            report("admitted", "")
            inner_writer.write(config.auth_frame)        # before any frame of the client's
            await inner_writer.drain()
            await asyncio.gather(_copy(reader, inner_writer), _copy(inner_reader, writer))
        finally:
            inner_writer.close()
    except (ConnectionError, OSError, asyncio.IncompleteReadError, asyncio.LimitOverrunError,
            asyncio.TimeoutError):
        pass
    finally:
        writer.close()


async def _copy(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    try:
        while True:
            data = await reader.read(65536)
            if not data:
                break
            writer.write(data)
            await writer.drain()
    except (ConnectionError, OSError):
        pass
    finally:
        try:
            writer.write_eof()
        except (OSError, RuntimeError):
            pass


if __name__ == "__main__":
    _gate_main()
