"""`hil log info|plot|export` on a real log written here with the session's channel layout:
a speed ramp with analytic values, so every number the commands print can be checked."""
from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from hil.logs.commands import (LogCommandError, _envelope, format_info, log_export, log_info, log_plot,
                              parse_signal)
from hil.logs.mcap_writer import McapLog

PERIOD_NS = 50_000
N = 4000  # 0.2 s at 50 us
RAMP_RPM_PER_S = 10_000.0


def _speed(k: int) -> float:
    return RAMP_RPM_PER_S * k * PERIOD_NS * 1e-9


@pytest.fixture(scope="module")
def run_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("log") / "run.mcap"
    with McapLog(path, metadata={"versions": {"hil": "0.1.0", "protocol": "1"},
                                 "profile": {"name": "paper-table-1", "dc_link_v": 70.0}}) as log:
        truth = log.add_fixed_channel("/plant/truth", "hil.PlantTruth",
                                      [("speed_rpm", "double"), ("torque_nm", "double"), ("i_a", "float")])
        sensors = log.add_fixed_channel("/plant/sensors", "hil.SensorSample",
                                        [("period", "fixed32"), ("adc_i1", "fixed32"), ("encoder", "fixed32")])
        telemetry = log.add_fixed_channel("/ctrl/telemetry", "hil.Telemetry",
                                          [("period", "fixed32"), ("torque_est_nm", "float")])
        frames_in = log.add_bytes_channel("/link/frames_in", "hil.FrameBatch")
        for k in range(N):
            t = k * PERIOD_NS
            truth.write(t, _speed(k), 0.5 * math.sin(k / 100), k / 1000)
            sensors.write(t, k, 2048 + k % 7, (k * 13) % 4096)
            if k % 2 == 0:
                telemetry.write(t, k, 0.25)
            if k % 20 == 19:
                frames_in.write(t, b"\x01\x02" * 20, 20)
            if k % 1000 == 0:
                log.write_json("/cmd", t, {"speed_ref_rpm": 1000.0 * k / 1000, "enable": True, "name": "step"})
    return path


def test_parse_signal_forms():
    assert parse_signal("plant.speed_rpm") == ("/plant/truth", "speed_rpm")
    assert parse_signal("sensor.adc_i1") == ("/plant/sensors", "adc_i1")
    assert parse_signal("ctrl.torque_est_nm") == ("/ctrl/telemetry", "torque_est_nm")
    assert parse_signal("/link/counters:crc.errors") == ("/link/counters", "crc.errors")
    # every name plans use, commands and step signals too (test_signal_vocabulary walks them all)
    assert parse_signal("cmd.speed_ref_rpm") == ("/cmd", "speed_ref_rpm")
    assert parse_signal("board.state") == ("/step/board.state", "value")
    for bad in ("speed_rpm", "plant.", "/plant/truth:", "plant/truth:x"):
        with pytest.raises(LogCommandError, match="TOPIC:FIELD"):
            parse_signal(bad)


def test_info_counts_duration_metadata_and_text(run_log):
    info = log_info(run_log)
    assert info["complete"]
    counts = {c["topic"]: c["count"] for c in info["channels"]}
    assert counts == {"/plant/truth": N, "/plant/sensors": N, "/ctrl/telemetry": N // 2,
                      "/link/frames_in": N // 20, "/cmd": 4}
    assert info["duration_s"] == pytest.approx((N - 1) * PERIOD_NS * 1e-9)
    rate = {c["topic"]: c["rate_hz"] for c in info["channels"]}
    assert rate["/plant/truth"] == pytest.approx(20_000) and rate["/ctrl/telemetry"] == pytest.approx(10_000)
    assert info["metadata"]["profile"] == {"name": "paper-table-1", "dc_link_v": "70.0"}
    text = format_info(info)
    assert "complete" in text and "UNFINISHED" not in text
    assert "/ctrl/telemetry  protobuf  hil.Telemetry" in text
    assert f"messages:   {2 * N + N // 2 + N // 20 + 4} in" in text
    assert "dc_link_v: 70.0" in text


def test_info_on_a_killed_log_says_it_is_unfinished(run_log, tmp_path):
    cut = tmp_path / "cut.mcap"
    blob = run_log.read_bytes()
    cut.write_bytes(blob[: len(blob) // 2])
    info = log_info(cut)
    assert not info["complete"] and 0 < info["message_count"] < 2 * N
    text = format_info(info)
    assert "UNFINISHED" in text and f"read up to byte {info['truncated_at']}" in text
    out = log_plot(cut, ["plant.speed_rpm"], tmp_path / "cut.png")
    assert not out["complete"] and out["signals"]["plant.speed_rpm"]["samples"] > 0


def test_plot_writes_a_png_of_the_chosen_window(run_log, tmp_path):
    png = tmp_path / "speed.png"
    out = log_plot(run_log, ["plant.speed_rpm", "ctrl.torque_est_nm", "/plant/sensors:adc_i1"], png,
                   t0=0.05, t1=0.1)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    speed = out["signals"]["plant.speed_rpm"]
    assert speed["samples"] == 1001  # 0.05 .. 0.1 s inclusive at 50 us
    assert speed["min"] == pytest.approx(RAMP_RPM_PER_S * 0.05) and speed["max"] == pytest.approx(RAMP_RPM_PER_S * 0.1)
    assert out["signals"]["ctrl.torque_est_nm"]["samples"] == 501
    assert out["signals"]["/plant/sensors:adc_i1"] == {"topic": "/plant/sensors", "field": "adc_i1",
                                                       "unit": "count", "samples": 1001, "min": 2048.0, "max": 2054.0}


def test_plot_errors_say_what_is_wrong(run_log, tmp_path):
    png = tmp_path / "x.png"
    with pytest.raises(LogCommandError, match="/plant/truth has no field 'speed'; fields: speed_rpm, torque_nm, i_a"):
        log_plot(run_log, ["plant.speed"], png)
    with pytest.raises(LogCommandError, match="no topic /nope; topics: /cmd, /ctrl/telemetry"):
        log_plot(run_log, ["/nope:x"], png)
    with pytest.raises(LogCommandError, match="/cmd:name is not numeric"):
        log_plot(run_log, ["/cmd:name"], png)
    with pytest.raises(LogCommandError, match="t1 < t0"):
        log_plot(run_log, ["plant.speed_rpm"], png, t0=0.1, t1=0.05)
    with pytest.raises(LogCommandError, match="no samples of plant.speed_rpm in the window 5.0 .. end s"):
        log_plot(run_log, ["plant.speed_rpm"], png, t0=5.0)
    with pytest.raises(LogCommandError, match="no signal to plot"):
        log_plot(run_log, [], png)
    assert not png.exists()


def test_envelope_keeps_every_peak_and_time_order():
    t = np.arange(100_000) * 1e-4
    v = np.zeros_like(t)
    v[12_345], v[77_777] = 5.0, -3.0
    tp, vp = _envelope(t, v, 4000)
    assert len(vp) <= 4000 + 100
    assert vp.max() == 5.0 and vp.min() == -3.0
    assert tp[np.argmax(vp)] == t[12_345] and tp[np.argmin(vp)] == t[77_777]
    assert np.all(np.diff(tp) >= 0)


def _read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def test_export_one_topic_round_trips_exactly(run_log, tmp_path):
    out = log_export(run_log, ["/plant/truth"], tmp_path / "truth.csv", t0=0.1)
    header, rows = _read_csv(tmp_path / "truth.csv")
    assert header == ["t_s", "log_time_ns", "/plant/truth:speed_rpm", "/plant/truth:torque_nm",
                      "/plant/truth:i_a"] == out["columns"]
    assert len(rows) == out["rows"] == N - 2000
    for row in rows[:50] + rows[-50:]:
        k = int(row[1]) // PERIOD_NS
        assert float(row[2]) == _speed(k)  # shortest repr reads back to the same double
        assert float(row[3]) == 0.5 * math.sin(k / 100)
        assert np.float32(row[4]) == np.float32(k / 1000)


def test_export_several_topics_merges_rows_in_time_order(run_log, tmp_path):
    out = log_export(run_log, ["ctrl.torque_est_nm", "/cmd", "plant.speed_rpm"], tmp_path / "mix.csv",
                     t0=0.0, t1=0.0501)
    header, rows = _read_csv(tmp_path / "mix.csv")
    assert header == ["t_s", "log_time_ns", "topic", "/ctrl/telemetry:torque_est_nm", "/cmd:speed_ref_rpm",
                      "/cmd:enable", "/cmd:name", "/plant/truth:speed_rpm"]
    times = [int(r[1]) for r in rows]
    assert times == sorted(times)
    by_topic = {}
    for r in rows:
        by_topic.setdefault(r[2], []).append(r)
    assert len(by_topic["/plant/truth"]) == 1003 and len(by_topic["/ctrl/telemetry"]) == 502
    assert [r[4] for r in by_topic["/cmd"]] == ["0.0", "1000.0"] and by_topic["/cmd"][0][5] == "True"
    for r in by_topic["/ctrl/telemetry"]:
        assert r[3] == "0.25" and r[4:] == ["", "", "", ""]
    # rows at the same log time keep the order the channels were named in
    first = [r[2] for r in rows if r[1] == "0"]
    assert first == ["/ctrl/telemetry", "/cmd", "/plant/truth"]
    assert out["rows"] == len(rows)


def test_export_bytes_are_hex_and_errors_name_the_problem(run_log, tmp_path):
    log_export(run_log, ["/link/frames_in"], tmp_path / "frames.csv", t1=0.001)
    header, rows = _read_csv(tmp_path / "frames.csv")
    assert header == ["t_s", "log_time_ns", "/link/frames_in:count", "/link/frames_in:data"]
    assert rows[0][2:] == ["20", "0102" * 20]
    with pytest.raises(LogCommandError, match="/plant/truth has no field 'nope'"):
        log_export(run_log, ["/plant/truth:nope"], tmp_path / "x.csv")
    with pytest.raises(LogCommandError, match="no channel to export"):
        log_export(run_log, [], tmp_path / "x.csv")
    with pytest.raises(LogCommandError, match="t0=nan is not a finite time"):
        log_export(run_log, ["/plant/truth"], tmp_path / "x.csv", t0=float("nan"))
    with pytest.raises(FileNotFoundError, match="no_dir"):
        log_export(run_log, ["/plant/truth"], tmp_path / "no_dir" / "x.csv")


def test_export_one_channel_with_its_own_t_s_field_names_each_column_once(tmp_path):
    """A message with its own t_s field (the session's /plant/truth has one): exported alone,
    the header holds t_s once and every field keeps its topic."""
    path = tmp_path / "own_t.mcap"
    with McapLog(path) as log:
        truth = log.add_fixed_channel("/plant/truth", "hil.PlantTruth",
                                      [("t_s", "double"), ("speed_rpm", "double")])
        for k in range(10):
            truth.write(k * PERIOD_NS, k * PERIOD_NS * 1e-9, 10.0 * k)
    for channels in (["/plant/truth"], ["plant.t_s", "plant.speed_rpm"]):
        log_export(path, channels, tmp_path / "one.csv")
        header, rows = _read_csv(tmp_path / "one.csv")
        assert header == ["t_s", "log_time_ns", "/plant/truth:t_s", "/plant/truth:speed_rpm"]
        assert len(set(header)) == len(header)
        assert [float(r[3]) for r in rows] == [10.0 * k for k in range(10)]
        assert [float(r[2]) for r in rows] == [k * PERIOD_NS * 1e-9 for k in range(10)]
