"""The control step on the Cortex-M4F target: instructions per ctl_step as the firmware
itself measures them with SysTick under QEMU's -icount (deterministic: one instruction per
count; docs/porting.md), for the DTC law per speed source (hil.links.qemu
measure_control_step) and for the FOC law (CONTROL_LAW = 1, answers DUTY) per speed source
with the encoder angle and with the EKF angle (FOC_ANGLE_SOURCE 0/1), on the same synthetic
rotating inputs (hil.links.qemu.rotating_samples); the firmware's flash and RAM, the
board layer alone (the echo firmware) and the protocol codec object alone; and the wall time of one SAMPLE -> answer exchange
through the bench's serial link over QEMU's TCP UART (median). `hil bench` prints it beside
the host figure of bench/stub.py (x86-64 instructions counted with callgrind)."""
from __future__ import annotations

import statistics
import time

from hil.links.qemu import (FIRMWARE_ELF, QemuBoard, QemuBoardError, build_firmware, firmware_size,
                            measure_control_step,
                            rotating_samples)


def _stats(values: list[int]) -> dict:
    return {"median": int(statistics.median(values)), "min": min(values), "max": max(values),
            "steps": len(values)}


def measure_foc_step(samples: int = 400, telemetry_divider: int = 10) -> dict:
    """Instructions per ctl_step with the FOC law, per (speed source, angle source), split
    into plain steps and the steps that also fill a TELEMETRY; the first step is left out.
    Also the wall time of each SAMPLE -> DUTY exchange (QEMU's UART over TCP)."""
    from protocol.links import open_link
    from protocol.messages import (CMD_ENABLE, PROTOCOL_VERSION, Command, Duty, Hello, ParamGet, ParamId,
                                   ParamSet, ParamValue, Role, SpeedSource)

    def exchange(link, msg, answer_type):
        link.send(msg)
        while True:
            reply = link.recv(5.0)
            if reply is None:
                raise QemuBoardError(f"the firmware did not answer {msg} within 5 s")
            if isinstance(reply, answer_type):
                return reply

    result: dict = {"telemetry_divider": telemetry_divider, "modes": {}}
    round_trips: list[float] = []
    with QemuBoard() as board, open_link(board.link_url) as link:
        result["hello_name"] = exchange(link, Hello(PROTOCOL_VERSION, Role.BENCH, 0, 50_000, name=b"measure"),
                                        Hello).name_str
        exchange(link, ParamSet(ParamId.TELEMETRY_DIVIDER, float(telemetry_divider)), ParamValue)
        exchange(link, ParamSet(ParamId.CONTROL_LAW, 1.0), ParamValue)
        for angle_name, angle in (("encoder_angle", 0.0), ("ekf_angle", 1.0)):
            exchange(link, ParamSet(ParamId.FOC_ANGLE_SOURCE, angle), ParamValue)
            for source in SpeedSource:
                link.send(Command(CMD_ENABLE, source, 100.0, 0.0, 0.0))
                plain, with_telemetry = [], []
                for sample in rotating_samples(samples):
                    t0 = time.perf_counter()
                    exchange(link, sample, Duty)
                    round_trips.append(time.perf_counter() - t0)
                    cycles = int(exchange(link, ParamGet(ParamId.CONTROL_STEP_CYCLES), ParamValue).value)
                    if sample.period == 0:
                        continue
                    (with_telemetry if sample.period % telemetry_divider == 0 else plain).append(cycles)
                result["modes"][f"{source.name.lower()}_speed_{angle_name}"] = {
                    "step": _stats(plain), "step_with_telemetry": _stats(with_telemetry)}
    result["sample_to_duty_round_trip_ms_median"] = round(statistics.median(round_trips) * 1e3, 3)
    result["round_trips"] = len(round_trips)
    return result


def run(quick: bool = False) -> dict:
    samples = 100 if quick else 400
    dtc = measure_control_step(samples=samples)
    foc = measure_foc_step(samples=samples, telemetry_divider=dtc["telemetry_divider"])
    # the board layer alone: the echo firmware, built here (a fresh checkout has only what the
    # QEMU tests built)
    echo = firmware_size(build_firmware(FIRMWARE_ELF.parent / "echo.elf"))
    codec = _codec_object_size()
    return {"icount_shift": dtc["icount_shift"], "hello_name": dtc["hello_name"],
            "telemetry_divider": dtc["telemetry_divider"],
            "instructions_per_ctl_step": {"dtc": dtc["modes"], "foc": foc["modes"]},
            "sample_to_duty_round_trip_ms_median": foc["sample_to_duty_round_trip_ms_median"],
            "round_trips": foc["round_trips"],
            "firmware": {k: dtc[k] for k in ("text_bytes", "data_bytes", "bss_bytes", "flash_bytes",
                                             "static_ram_bytes")},
            "echo_firmware_board_layer": echo,
            "protocol_codec_object_cortex_m4f": codec}


def _codec_object_size() -> dict:
    """The C codec alone for the Cortex-M4F (`make -C protocol/c arm`: -Os), arm-none-eabi-size."""
    import subprocess
    from pathlib import Path

    c_dir = Path(__file__).resolve().parent.parent / "protocol" / "c"
    subprocess.run(["make", "-s", "-C", str(c_dir), "arm"], check=True, capture_output=True)
    out = subprocess.run(["arm-none-eabi-size", str(c_dir / "build" / "arm" / "hil_proto.o")],
                         capture_output=True, text=True, check=True).stdout.splitlines()[1].split()
    return {"text_bytes": int(out[0]), "data_bytes": int(out[1]), "bss_bytes": int(out[2])}
