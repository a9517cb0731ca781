"""What a link's port is, read from Linux sysfs, and what its latency does to a run.

``inspect_link("serial:/dev/ttyUSB0")`` follows /sys/class/tty/ttyUSB0/device to the driver
bound to the port (ftdi_sio, cdc_acm, cp210x, ch341, ...), as pyserial's
serial.tools.list_ports_linux.SysFS does (which reads /sys itself: here the root is a
parameter, so tests run against a fake tree), and reads the FTDI ``latency_timer`` and the USB
speed. A /dev/pts/N is a pseudo-terminal; ``can:socketcan:can0`` is looked up under
/sys/class/net (the bitrate comes from the link string or ``ip -details link``).

``advice(info)`` names the cause of a poor lockstep rate and its fix (the command and the
udev rule); ``set_latency_timer`` writes the sysfs file where the user may.
"""
from __future__ import annotations

import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import parse_qsl

from hil.links.wire import (FTDI_DEFAULT_LATENCY_TIMER_S, PRESETS, USB_HIGH_SPEED_MICROFRAME_S,
                            WireModel, ftdi)

FTDI_DEFAULT_MS = round(FTDI_DEFAULT_LATENCY_TIMER_S * 1e3)

SYSFS_ROOT = Path("/sys")
#: ASYNC_LOW_LATENCY in struct serial_struct's flags (linux/tty_flags.h); pyserial's
#: Serial.set_low_latency_mode sets the same bit.
ASYNC_LOW_LATENCY = 0x2000
#: The USB serial drivers this module knows, by the name sysfs gives them.
KNOWN_DRIVERS = {"ftdi_sio": "FTDI USB-serial adapter", "cdc_acm": "CDC-ACM (native USB port)",
                 "cp210x": "Silicon Labs CP210x USB-serial adapter",
                 "ch341": "WCH CH340/CH341 USB-serial adapter"}
UDEV_RULE_FILE = "/etc/udev/rules.d/99-ftdi-latency.rules"


@dataclass
class AdapterInfo:
    """What is between the bench and the board, as far as the host can tell."""

    # ftdi_sio | cdc_acm | cp210x | ch341 (a USB-serial driver), serial (another tty), pty,
    # can, process (a board in this process or an emulator), unknown (no sysfs entry)
    kind: str
    port: str = ""                 # /dev/ttyUSB0, can0, ...
    driver: str = ""
    description: str = ""
    latency_timer_ms: int | None = None       # FTDI
    low_latency: bool | None = None           # ASYNC_LOW_LATENCY on the open port
    usb_speed_mbps: float | None = None       # 12 full speed, 480 high speed
    usb_id: str = ""                          # vid:pid
    can_bitrate: int | None = None
    baud: int | None = None
    sysfs_path: str = ""                      # the port's device directory
    tty_name: str = ""                        # its name in sysfs (ttyUSB0)
    wire: WireModel | None = None             # a modelled wire (wire= on the link), if any
    notes: list[str] = field(default_factory=list)

    def metadata(self) -> dict[str, str]:
        """For the log's metadata: every known setting as text."""
        out = {"kind": self.kind, "port": self.port, "driver": self.driver,
               "description": self.description}
        for key in ("latency_timer_ms", "low_latency", "usb_speed_mbps", "can_bitrate", "baud"):
            value = getattr(self, key)
            if value is not None:
                out[key] = str(value)
        if self.usb_id:
            out["usb_id"] = self.usb_id
        if self.wire is not None:
            out.update({f"modelled.{k}": v for k, v in self.wire.settings().items()})
        return out

    def expected_wire(self) -> WireModel | None:
        """The wire model this adapter behaves like (the modelled one if given)."""
        if self.wire is not None:
            return self.wire
        baud = self.baud
        if self.kind == "ftdi_sio":
            timer = self.latency_timer_ms if self.latency_timer_ms is not None else FTDI_DEFAULT_MS
            return ftdi(max(1, min(255, timer)), baud or 2_000_000)
        if self.kind == "cdc_acm":
            name = "cdc-hs" if (self.usb_speed_mbps or 12) >= 480 else "cdc-fs"
            return PRESETS[name](None)
        if self.kind in ("cp210x", "ch341"):
            return PRESETS["cp210x" if self.kind == "cp210x" else "ch340"](baud or 2_000_000)
        return None


@dataclass
class Advice:
    cause: str
    fix: str = ""          # empty: nothing the host can change
    poor: bool = False     # the adapter caps the lockstep rate far below the line's


# --------------------------------------------------------------------- reading sysfs

def _read(path: Path) -> str | None:
    try:
        return path.read_text().strip()
    except OSError:
        return None


def _usb_device_dir(device_dir: Path) -> Path | None:
    """The USB device above a tty's device directory (interface -> device), pyserial's way:
    usb-serial ports sit one level below the interface, cdc_acm's tty at the interface."""
    for candidate in (device_dir.parent, device_dir.parent.parent, device_dir):
        if (candidate / "idVendor").exists():
            return candidate
    return None


def inspect_tty(device: str, sysfs_root: Path = SYSFS_ROOT) -> AdapterInfo:
    """What the tty ``device`` (/dev/ttyUSB0, /dev/ttyACM0, /dev/pts/3) is, from sysfs."""
    real = os.path.realpath(device) if os.path.islink(device) else device
    # the port's sysfs name: a udev link's target (/dev/serial/by-id/... -> ttyUSB0), as
    # pyserial resolves it, unless the link's own name has an entry
    names = [os.path.basename(device), os.path.basename(real)]
    name = next((n for n in names if (sysfs_root / "class" / "tty" / n / "device").exists()),
                None)
    if name is None and (real.startswith("/dev/pts/") or os.path.basename(real) == "ptmx"
                         or _is_pty_major(real)):
        return AdapterInfo("pty", port=device, driver="pty", description="pseudo-terminal "
                           "(a board process on this machine): no USB latency")
    tty_dir = sysfs_root / "class" / "tty" / (name or names[-1])
    device_link = tty_dir / "device"
    if name is None:
        return AdapterInfo("unknown", port=device, description=f"no sysfs entry "
                           f"{tty_dir} (not a local tty, or not Linux)")
    device_dir = Path(os.path.realpath(device_link))
    driver = os.path.basename(os.path.realpath(device_dir / "driver")) \
        if (device_dir / "driver").exists() else ""
    if not driver:   # cdc_acm binds to the interface the tty's device link points at
        driver = os.path.basename(os.path.realpath(device_dir.parent / "driver")) \
            if (device_dir.parent / "driver").exists() else ""
    description = KNOWN_DRIVERS.get(driver, f"serial port (driver {driver or 'unknown'})")
    info = AdapterInfo(driver if driver in KNOWN_DRIVERS else "serial", port=device,
                       driver=driver, description=description, sysfs_path=str(device_dir),
                       tty_name=name)
    timer = _read(device_dir / "latency_timer")
    if timer is not None and timer.isdigit():
        info.latency_timer_ms = int(timer)
    usb = _usb_device_dir(device_dir)
    if usb is not None:
        speed = _read(usb / "speed")
        try:
            info.usb_speed_mbps = float(speed) if speed else None
        except ValueError:
            pass
        vid, pid = _read(usb / "idVendor"), _read(usb / "idProduct")
        if vid and pid:
            info.usb_id = f"{vid}:{pid}"
        product = _read(usb / "product")
        if product:
            info.description += f" ({product})"
    if sysfs_root == Path("/sys"):
        _pyserial_details(real, info)
    return info


def _pyserial_details(device: str, info: AdapterInfo) -> None:
    """pyserial's own view of a local port (serial.tools.list_ports_linux): its USB
    description and hardware id (VID:PID, serial number, location) for the report."""
    try:
        from serial.tools.list_ports_linux import SysFS

        port = SysFS(device)
    except Exception:  # noqa: BLE001 - only a description: never fatal
        return
    if port.vid is not None and not info.usb_id:
        info.usb_id = f"{port.vid:04x}:{port.pid:04x}"
    if port.hwid and port.hwid != "n/a":
        info.notes.append(f"pyserial: {port.description} [{port.hwid}]")


def _is_pty_major(device: str) -> bool:
    """Unix98 pty slaves are char majors 136-143 (Documentation/admin-guide/devices.txt)."""
    try:
        st = os.stat(device)
    except OSError:
        return False
    return stat.S_ISCHR(st.st_mode) and 136 <= os.major(st.st_rdev) <= 143


def inspect_can(interface: str, channel: str, bitrate: int | None,
                sysfs_root: Path = SYSFS_ROOT) -> AdapterInfo:
    """A python-can interface: socketcan's netdevice under /sys/class/net, an slcan's tty,
    or just the name of another interface."""
    info = AdapterInfo("can", port=channel, driver=interface, can_bitrate=bitrate,
                       description=f"CAN through python-can interface '{interface}'")
    if interface == "slcan" and channel.startswith("/dev/"):
        tty = inspect_tty(channel, sysfs_root)
        info.description += f" on {tty.description}"
        info.notes.append(f"the slcan adapter's serial side: {tty.description}")
        info.latency_timer_ms = tty.latency_timer_ms
        info.tty_name = tty.tty_name
        info.driver = f"slcan/{tty.driver}" if tty.driver else "slcan"
        info.sysfs_path = tty.sysfs_path
        return info
    net = sysfs_root / "class" / "net" / channel
    if interface == "socketcan" and net.exists():
        device = net / "device"
        if (device / "driver").exists():
            info.driver = os.path.basename(os.path.realpath(device / "driver"))
            info.description += f", driver {info.driver}"
        elif _read(net / "type") == "280":
            info.driver = "vcan" if channel.startswith("vcan") else info.driver
        info.sysfs_path = str(net)
        if bitrate is None and sysfs_root == Path("/sys"):    # this machine's interface
            info.can_bitrate = can_bitrate_from_ip(channel)
    return info


def can_bitrate_from_ip(channel: str, run=None) -> int | None:
    """The bitrate of a socketcan interface from `ip -details -json link show` (iproute2), or
    None where it cannot be read (no ip, a virtual interface)."""
    import json
    import subprocess

    run = run or (lambda argv: subprocess.run(argv, capture_output=True, text=True,
                                              timeout=2.0).stdout)
    try:
        out = json.loads(run(["ip", "-details", "-json", "link", "show", channel]) or "[]")
        return int(out[0]["linkinfo"]["info_data"]["bittiming"]["bitrate"])
    except Exception:  # noqa: BLE001 - no ip, no such interface, a virtual one, a timeout
        return None


def inspect_link(spec: str, sysfs_root: Path = SYSFS_ROOT, wire: WireModel | None = None
                 ) -> AdapterInfo:
    """What a link string's port is (serial:, can:, a bare device path; anything else is a
    board on this machine), with the modelled wire if the link has one."""
    info = _inspect(spec, sysfs_root)
    if wire is not None:
        info.wire = wire
        info.notes.append(f"modelled wire {wire.describe()}")
    return info


def _inspect(spec: str, sysfs_root: Path) -> AdapterInfo:
    if spec.startswith("can:"):
        head, _, query = spec[4:].partition("?")
        interface, _, channel = head.partition(":")
        options = dict(parse_qsl(query))
        bitrate = None
        if "bitrate" in options:
            try:
                bitrate = int(options["bitrate"], 0)
            except ValueError:
                bitrate = None
        return inspect_can(interface, channel, bitrate, sysfs_root)
    if spec.startswith("serial:") or spec.startswith("/dev/"):
        port = spec[7:] if spec.startswith("serial:") else spec
        path, _, query = port.partition("?")
        if "://" in path:
            return AdapterInfo("serial", port=path, description="pyserial URL (network or "
                               "loopback): no USB adapter on this machine")
        info = inspect_tty(path, sysfs_root)
        for key, value in parse_qsl(query):
            if key in ("baud", "baudrate") and value.isdigit():
                info.baud = int(value)
        return info
    if spec.partition("?")[0] in ("stub-pty", "stub-can") or spec.startswith("exec:"):
        return AdapterInfo("pty", port=spec, driver="pty",
                           description="pseudo-terminal to a board process on this machine")
    return AdapterInfo("process", port=spec, description="a board in this process or an "
                       "emulator: no adapter")


def read_low_latency(fd: int | None) -> bool | None:
    """The ASYNC_LOW_LATENCY flag of an open tty (TIOCGSERIAL), None where the port has no
    serial_struct (a pseudo-terminal, a URL) or this is not Linux."""
    if fd is None:
        return None
    try:
        import array
        import fcntl
        import termios

        buf = array.array("i", [0] * 32)
        fcntl.ioctl(fd, termios.TIOCGSERIAL, buf)
        return bool(buf[4] & ASYNC_LOW_LATENCY)
    except (ImportError, AttributeError, OSError):
        return None


# -------------------------------------------------------------------------- advice

def udev_rule() -> str:
    return ('ACTION=="add", SUBSYSTEM=="usb-serial", DRIVER=="ftdi_sio", '
            'ATTR{latency_timer}="1"')


def latency_timer_fix(info: AdapterInfo) -> str:
    real = bool(info.tty_name) and info.wire is None
    name = info.tty_name if real else "ttyUSBn"
    now = f"or `hil probe {_link_of(info)} --set-latency-timer 1`" if real else \
        "on the real adapter's port; here the wire is modelled: wire=ftdi-1ms"
    return (f"echo 1 | sudo tee /sys/bus/usb-serial/devices/{name}/latency_timer   (now; {now}),"
            f" and for good: the udev rule\n"
            f"    {udev_rule()}\n    in {UDEV_RULE_FILE}, then `sudo udevadm control --reload` "
            f"and replug (or open the port with pyserial's set_low_latency_mode(True))")


def _link_of(info: AdapterInfo) -> str:
    return f"serial:{info.port}" if "/" in info.port else info.port


def advice(info: AdapterInfo) -> Advice:
    """The cause of the lockstep rate this adapter allows, and the fix where there is one."""
    wire = info.expected_wire()
    rate = f"{wire.lockstep_rate_hz():.0f} periods/s" if wire is not None else ""
    modelled = "modelled " if info.wire is not None else ""
    if (info.wire is not None and info.wire.driver == "ftdi_sio") or info.kind == "ftdi_sio":
        timer = info.latency_timer_ms
        if info.wire is not None and info.wire.driver == "ftdi_sio":
            timer = round(info.wire.back.latency_s * 1e3)
        if timer is None:
            return Advice(f"FTDI adapter, latency timer unreadable (default {FTDI_DEFAULT_MS} ms: "
                          f"about {rate} in lockstep)", latency_timer_fix(info), poor=True)
        if timer > 1:
            return Advice(f"{modelled}FTDI adapter with latency timer {timer} ms: the chip holds "
                          f"each answer up to {timer} ms (unless 62 bytes fill a USB packet "
                          f"first), so lockstep runs at most {rate} with answers alone",
                          latency_timer_fix(info), poor=True)
        return Advice(f"{modelled}FTDI adapter, latency timer 1 ms (the least): about {rate} in "
                      f"lockstep; for more, a board with a native high-speed USB port "
                      f"(CDC-ACM, 125 us microframes)")
    kind = info.wire.driver if info.wire is not None else info.kind
    if kind == "cdc_acm":
        hs = (wire is not None and wire.back.grid_s <= USB_HIGH_SPEED_MICROFRAME_S)
        frame = "125 us high-speed microframes" if hs else "1 ms full-speed frames"
        return Advice(f"{modelled}CDC-ACM port: answers arrive on {frame}, about {rate} in "
                      f"lockstep at most" + ("" if hs else "; a high-speed USB port allows 8x "
                                              "more"))
    if kind in ("cp210x", "ch341"):
        name = "CP210x" if kind == "cp210x" else "CH340/CH341"
        return Advice(f"{modelled}{name} adapter: no latency timer the host can set; answers "
                      f"come on 1 ms USB frames at best (about {rate}); its own buffering is not "
                      f"documented: measure it with `hil probe`", "an FTDI adapter with its "
                      f"latency timer at 1 ms, or a board's native USB port, if the rate "
                      f"measured is poor")
    if info.wire is not None:
        return Advice(f"modelled wire {info.wire.describe()}: about {rate} in lockstep")
    if info.kind == "pty":
        return Advice("pseudo-terminal: no adapter; the round trip is the board process's and "
                      "the kernel's")
    if info.kind == "can" and (info.latency_timer_ms or 0) > 1:      # slcan on an FTDI
        return Advice(f"slcan adapter on an FTDI with latency timer {info.latency_timer_ms} ms: "
                      f"each answer held up to {info.latency_timer_ms} ms",
                      latency_timer_fix(info), poor=True)
    if info.kind == "can":
        bitrate = f"{info.can_bitrate} bit/s" if info.can_bitrate else "bitrate unknown"
        text = f"CAN ({info.driver}, {bitrate}): SAMPLE and GATES take ~200-240 us at 1 Mbit/s"
        if info.can_bitrate and info.can_bitrate < 1_000_000:
            text += f", {1_000_000 / info.can_bitrate:g}x that at this bitrate"
        return Advice(text + "; a USB-CAN interface adds its USB frames (1 ms at full speed)",
                      "bitrate=1000000 on the link and the board" if info.can_bitrate and
                      info.can_bitrate < 1_000_000 else "",
                      poor=bool(info.can_bitrate and info.can_bitrate < 500_000))
    return Advice(info.description or "unknown port")


def warning(info: AdapterInfo) -> str | None:
    """The start-up warning for a session: None when the adapter needs nothing."""
    found = advice(info)
    if not found.poor:
        return None
    text = f"{info.port or 'link'}: {found.cause}"
    if found.fix:
        text += f"; fix: {found.fix}"
    return text


def set_latency_timer(info: AdapterInfo, ms: int, sysfs_root: Path = SYSFS_ROOT) -> str:
    """Writes an FTDI port's latency_timer (1..255 ms); returns what was done, raises
    PermissionError/ValueError naming the file and the fix."""
    if info.kind != "ftdi_sio" or not info.sysfs_path:
        raise ValueError(f"{info.port}: not an FTDI port ({info.kind}): it has no latency timer")
    if not 1 <= ms <= 255:
        raise ValueError(f"latency timer {ms} ms is not 1..255")
    path = Path(info.sysfs_path) / "latency_timer"
    try:
        path.write_text(f"{ms}\n")
    except PermissionError as exc:
        raise PermissionError(f"{path}: permission denied; run `echo {ms} | sudo tee {path}` "
                              f"or install the udev rule: {udev_rule()}") from exc
    info.latency_timer_ms = int(_read(path) or ms)
    return f"{path}: latency timer now {info.latency_timer_ms} ms"


__all__ = ["AdapterInfo", "Advice", "inspect_link", "inspect_tty", "inspect_can", "advice",
           "warning", "set_latency_timer", "read_low_latency", "udev_rule", "SYSFS_ROOT",
           "can_bitrate_from_ip"]
