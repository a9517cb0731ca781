"""A fake Linux sysfs tree laid out as the kernel lays out a USB-serial port, a CDC-ACM port
and a socketcan interface (the links /sys/class/tty/NAME/device and /sys/class/net/NAME/device
into /sys/devices, the driver links into /sys/bus/.../drivers)."""
from __future__ import annotations

from pathlib import Path

USB_IDS = {"ftdi_sio": ("0403", "6001", "FT232R USB UART"),
           "cp210x": ("10c4", "ea60", "CP2102 USB to UART Bridge Controller"),
           "ch341": ("1a86", "7523", "USB Serial"),
           "cdc_acm": ("0483", "5740", "STM32 Virtual ComPort"),
           "gs_usb": ("1d50", "606f", "candleLight USB to CAN adapter")}


def _usb_device(root: Path, bus_port: str, driver: str, speed: str) -> tuple[Path, Path]:
    usb = root / "devices" / "pci0000:00" / "0000:00:14.0" / "usb1" / bus_port
    interface = usb / f"{bus_port}:1.0"
    interface.mkdir(parents=True)
    vid, pid, product = USB_IDS[driver]
    for name, value in (("idVendor", vid), ("idProduct", pid), ("product", product),
                        ("speed", speed), ("bNumInterfaces", " 1")):
        (usb / name).write_text(value + "\n")
    return usb, interface


def _driver_link(root: Path, where: Path, bus: str, driver: str) -> None:
    target = root / "bus" / bus / "drivers" / driver
    target.mkdir(parents=True, exist_ok=True)
    (where / "driver").symlink_to(target)


def add_tty(root: Path, name: str, driver: str, latency_timer_ms: int | None = None,
            speed: str = "12", bus_port: str | None = None) -> Path:
    """/sys/class/tty/NAME for a port of ``driver``; returns the port's device directory."""
    ports = len(list(root.glob("devices/*/*/usb1/*")))
    usb, interface = _usb_device(root, bus_port or f"1-{ports + 1}", driver, speed)
    if driver == "cdc_acm":         # the tty's device is the interface cdc_acm binds to
        device = interface
        _driver_link(root, interface, "usb", driver)
        (interface / "tty" / name).mkdir(parents=True)
    else:                           # usb-serial: a port device below the interface
        device = interface / name
        device.mkdir()
        _driver_link(root, device, "usb-serial", driver)
        _driver_link(root, interface, "usb", driver)
    if latency_timer_ms is not None:
        (device / "latency_timer").write_text(f"{latency_timer_ms}\n")
    tty = root / "class" / "tty" / name
    tty.mkdir(parents=True)
    (tty / "device").symlink_to(device)
    return device


def add_can(root: Path, name: str = "can0", driver: str = "gs_usb") -> Path:
    """/sys/class/net/NAME for a USB-CAN interface of ``driver``."""
    usb, interface = _usb_device(root, "1-9", driver, "12")
    _driver_link(root, interface, "usb", driver)
    net = root / "class" / "net" / name
    net.mkdir(parents=True)
    (net / "type").write_text("280\n")
    (net / "device").symlink_to(interface)
    return net
