"""`hil log info|plot|export`: what is in a run log, a PNG of chosen signals, CSV of chosen channels.

A *signal* names one field of one topic: ``/plant/truth:speed_rpm``, or the name a plan
uses (``plant.speed_rpm``, ``cmd.speed_ref_rpm``, ``board.state``: test_plans/README.md,
Signals), resolved by the recorder's own mapping (hil/logs/recorder.py log_source) and given
the unit the plan runner gives it (hil/plans/signals.py SignalSet.from_arrays). Time
windows are seconds from the log's first message. Unfinished (killed) logs are read up
to their last finished chunk, and the commands say so.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from hil.logs.reader import LogData, TopicData, log_summary, read_log
from hil.logs.recorder import LOG_TOPICS, STEP_FIELD, is_held, log_source, plan_name, unit_of
from hil.plans.signals import SIGNAL_CATALOG, SignalSet

_PLOT_POINTS = 4000  # per signal; longer series are reduced to a min/max envelope


class LogCommandError(ValueError):
    """A bad signal, channel or window given to a log command."""


def parse_signal(spec: str) -> tuple[str, str]:
    """``topic:field`` or a plan's signal name (``plant.speed_rpm``) -> (topic, field)."""
    spec = spec.strip()
    if ":" in spec:
        topic, _, name = spec.partition(":")
        if topic.startswith("/") and name:
            return topic, name
    elif not spec.startswith("/"):
        source = log_source(spec)
        if source is not None and (source[1] != STEP_FIELD or spec in SIGNAL_CATALOG):
            return source
        group, _, field = spec.partition(".")
        if source is not None and group in LOG_TOPICS:   # its topic's fields say what there is
            return LOG_TOPICS[group], field
        if source is not None:
            import difflib      # an unknown name's message only

            close = difflib.get_close_matches(spec, list(SIGNAL_CATALOG), n=1, cutoff=0.75)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise LogCommandError(f"signal {spec!r} is not a signal plans name (test_plans/"
                                  f"README.md, Signals){hint}")
    raise LogCommandError(
        f"signal {spec!r}: write TOPIC:FIELD (e.g. /plant/truth:speed_rpm) or a plan's signal "
        f"name ({', '.join(p + '.FIELD' for p in LOG_TOPICS)}, board.state, ...)")


def field_unit(topic: str, field: str) -> str:
    """The unit of `field` of `topic`: for a plan's signal the one the plan runner gives it
    (SignalSet.from_arrays: the recorder's unit, else the catalogue's), else from the
    field's name ('' when it says none)."""
    name = plan_name(topic, field)
    if name is None:
        return unit_of(field)
    empty = np.empty(0)
    return SignalSet.from_arrays({name: (empty, empty, unit_of(field))})[name].unit


# -- info -----------------------------------------------------------------------------------------

def log_info(path: str | Path) -> dict[str, Any]:
    """Channels, message counts, duration, metadata and attachments (see log_summary); each
    channel's ``fields`` with their ``unit`` and the ``signal`` name plans use (or None)."""
    info = log_summary(path)
    for ch in info["channels"]:
        ch["fields"] = [{"field": f, "unit": field_unit(ch["topic"], f),
                         "signal": plan_name(ch["topic"], f)} for f in ch["field_names"]]
        del ch["field_names"]
    return info


def format_info(info: dict[str, Any]) -> str:
    """Text rendering of :func:`log_info`."""
    lines = [f"file:       {info['path']} ({_size(info['size_bytes'])}, "
             f"{'complete' if info['complete'] else 'UNFINISHED'})"]
    if not info["complete"]:
        lines.append(f"            {info['note']}; read up to byte {info['truncated_at']}, "
                     f"the last finished chunk")
    lines.append(f"written by: {info['library'] or '?'}")
    lines.append(f"duration:   {info['duration_s']:.6f} s"
                 + (f" (first message at {info['start_ns']} ns log time)" if info["start_ns"] else ""))
    lines.append(f"messages:   {info['message_count']} in {info['chunk_count']} chunks "
                 f"({', '.join(info['compression']) or 'no chunks'})")
    rows = [("topic", "encoding", "schema", "messages", "rate Hz", "first s", "last s")]
    for ch in info["channels"]:
        rows.append((ch["topic"], ch["message_encoding"], ch["schema_name"], str(ch["count"]),
                     f"{ch['rate_hz']:.1f}" if ch["rate_hz"] else "-",
                     f"{ch['first_s']:.6f}" if ch["first_s"] is not None else "-",
                     f"{ch['last_s']:.6f}" if ch["last_s"] is not None else "-"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines.append("channels:")
    for r in rows:
        lines.append("  " + "  ".join(c.ljust(w) if i < 3 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths))))
    lines.append("fields (topic:field, unit, the name plans use):")
    fields = [(f"{ch['topic']}:{f['field']}", f"[{f['unit'] or '-'}]", f["signal"] or "")
              for ch in info["channels"] for f in ch["fields"]]
    w0 = max((len(r[0]) for r in fields), default=0)
    w1 = max((len(r[1]) for r in fields), default=0)
    lines += [f"  {a.ljust(w0)}  {b.ljust(w1)}  {c}".rstrip() for a, b, c in fields]
    if info["metadata"]:
        lines.append("metadata:")
        for name, data in info["metadata"].items():
            lines.append(f"  {name}:")
            for key, value in data.items():
                lines.append(f"    {key}: {value}")
    if info["attachments"]:
        lines.append("attachments:")
        for att in info["attachments"]:
            lines.append(f"  {att['name']} ({att['media_type']}, {_size(att['size_bytes'])})")
    return "\n".join(lines)


def _size(n: int) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return str(n)


# -- selecting data ---------------------------------------------------------------------------------

def _check_window(t0: float | None, t1: float | None) -> None:
    for name, value in (("t0", t0), ("t1", t1)):
        if value is not None and not math.isfinite(value):
            raise LogCommandError(f"{name}={value} is not a finite time in seconds")
    if t0 is not None and t1 is not None and t1 < t0:
        raise LogCommandError(f"time window t0={t0} s .. t1={t1} s is empty (t1 < t0)")


def _read(path: str | Path, topics: list[str], t0: float | None, t1: float | None) -> LogData:
    _check_window(t0, t1)
    try:
        return read_log(path, topics, t0, t1)
    except KeyError as exc:  # unknown topic: the message lists the topics there are
        raise LogCommandError(exc.args[0]) from None


def _field(data: LogData, topic: str, name: str, spec: str) -> np.ndarray:
    td: TopicData = data[topic]
    if name not in td.fields:
        raise LogCommandError(f"signal {spec!r}: {topic} has no field {name!r}; "
                              f"fields: {', '.join(td.fields) or '(none)'}")
    return td.fields[name]


# -- plot -----------------------------------------------------------------------------------------

def log_plot(path: str | Path, signals: list[str], out_png: str | Path,
             t0: float | None = None, t1: float | None = None) -> dict[str, Any]:
    """One stacked subplot per signal over [t0, t1] s, written to `out_png`."""
    series, data = plot_series(path, signals, t0, t1)
    return _draw(path, series, data, out_png)


def plot_series(path: str | Path, signals: list[str], t0: float | None = None,
                t1: float | None = None) -> tuple[list[tuple], LogData]:
    """What `log_plot` draws: (spec, topic, field, t_s, float64 values) per signal, and the
    data read; a signal that does not resolve to numbers raises LogCommandError."""
    if not signals:
        raise LogCommandError("no signal to plot: name at least one (e.g. plant.speed_rpm)")
    parsed = [(spec, *parse_signal(spec)) for spec in signals]
    topics = list(dict.fromkeys(topic for _, topic, _ in parsed))
    data = _read(path, topics, t0, t1)
    series = []
    for spec, topic, name in parsed:
        values = _field(data, topic, name, spec)
        if values.dtype == object or values.dtype.kind not in "biuf":
            raise LogCommandError(f"signal {spec!r}: {topic}:{name} is not numeric, it cannot be plotted")
        series.append((spec, topic, name, data[topic].t_s, values.astype(np.float64)))
    if all(len(s[3]) == 0 for s in series):
        window = f" in the window {t0 if t0 is not None else 'start'} .. {t1 if t1 is not None else 'end'} s"
        raise LogCommandError(f"{path}: no samples of {', '.join(signals)}{window}")
    return series, data


def _draw(path: str | Path, series: list[tuple], data: LogData, out_png: str | Path) -> dict[str, Any]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(series), 1, sharex=True, squeeze=False,
                             figsize=(10, 1.0 + 2.0 * min(len(series), 8)))
    for ax, (spec, topic, name, t, v) in zip(axes[:, 0], series):
        unit = field_unit(topic, name)
        if is_held(topic):      # changes of a held value: a step from each to the next
            ax.step(t, v, where="post", linewidth=0.8)
        else:
            tp, vp = _envelope(t, v, _PLOT_POINTS)
            ax.plot(tp, vp, linewidth=0.8)
        ax.set_ylabel(f"{name} [{unit}]" if unit else name)
        signal = plan_name(topic, name)
        ax.set_title(f"{topic}:{name}" + (f" ({signal})" if signal else ""), fontsize=9, loc="left")
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time from log start [s]")
    note = "" if data.complete else " (unfinished log, read to its last chunk)"
    fig.suptitle(f"{Path(path).name}{note}", fontsize=10)
    fig.tight_layout()
    out_png = Path(out_png)
    fig.savefig(out_png, dpi=100)
    plt.close(fig)
    return {"out_png": str(out_png), "complete": data.complete,
            "signals": {spec: {"topic": topic, "field": name, "unit": field_unit(topic, name),
                               "samples": int(len(t)),
                               "min": float(np.nanmin(v)) if len(v) else None,
                               "max": float(np.nanmax(v)) if len(v) else None}
                        for spec, topic, name, t, v in series}}


def _envelope(t: np.ndarray, v: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray]:
    """Min and max of each bin, in time order, so that decimation keeps every peak."""
    n = len(v)
    if n <= points:
        return t, v
    bins = points // 2
    per = n // bins
    m = bins * per
    tv = t[:m].reshape(bins, per)
    vv = v[:m].reshape(bins, per)
    imin = np.nanargmin(np.where(np.isnan(vv), np.inf, vv), axis=1)
    imax = np.nanargmax(np.where(np.isnan(vv), -np.inf, vv), axis=1)
    first = np.minimum(imin, imax)
    second = np.maximum(imin, imax)
    rows = np.arange(bins)
    tt = np.stack([tv[rows, first], tv[rows, second]], axis=1).ravel()
    vo = np.stack([vv[rows, first], vv[rows, second]], axis=1).ravel()
    return np.concatenate([tt, t[m:]]), np.concatenate([vo, v[m:]])


# -- export ---------------------------------------------------------------------------------------

def log_export(path: str | Path, channels: list[str], out_csv: str | Path,
               t0: float | None = None, t1: float | None = None) -> dict[str, Any]:
    """CSV of the chosen channels over [t0, t1] s.

    Each item of `channels` is a topic (all its fields) or a signal (one field: TOPIC:FIELD or
    a plan's signal name; `units` in the result gives each column's). Columns:
    ``t_s, log_time_ns`` (the log's time) then the fields, always named ``topic:field`` (a
    message's own ``t_s`` field is ``/plant/truth:t_s``, never a second ``t_s`` column); with
    several topics also ``topic``, and rows of all topics are merged in log-time order, each
    row filling only its own topic's columns.
    """
    if not channels:
        raise LogCommandError("no channel to export: name at least one topic (e.g. /plant/truth)")
    selection: dict[str, list[str] | None] = {}  # topic -> fields (None = all)
    for item in channels:
        item = item.strip()
        if item.startswith("/") and ":" not in item:
            selection[item] = None
        else:
            topic, name = parse_signal(item)
            if topic not in selection:
                selection[topic] = [name]
            elif selection[topic] is not None and name not in selection[topic]:
                selection[topic].append(name)
    data = _read(path, list(selection), t0, t1)
    multi = len(selection) > 1
    columns = ["t_s", "log_time_ns"] + (["topic"] if multi else [])
    blocks = []
    for topic, names in selection.items():
        td = data[topic]
        names = list(td.fields) if names is None else names
        for name in names:
            _field(data, topic, name, f"{topic}:{name}")
        header = [f"{topic}:{n}" for n in names]
        offset = len(columns)
        columns += header
        blocks.append((topic, td, names, offset))
    times = np.concatenate([b[1].log_time_ns for b in blocks]) if blocks else np.empty(0, np.int64)
    order = np.argsort(times, kind="stable")
    cells: list[list[str]] = []
    for topic, td, names, offset in blocks:
        cols = [_text_column(td.t_s), [str(x) for x in td.log_time_ns.tolist()]]
        if multi:
            cols.append([topic] * len(td))
        cols += [_text_column(td.fields[n]) for n in names]
        row_template = [""] * len(columns)
        fixed = [0, 1] + ([2] if multi else [])
        targets = fixed + list(range(offset, offset + len(names)))
        for values in zip(*cols):
            row = row_template.copy()
            for i, value in zip(targets, values):
                row[i] = value
            cells.append(row)
    out_csv = Path(out_csv)
    with open(out_csv, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        writer.writerows(cells[i] for i in order.tolist())
    units = {f"{topic}:{n}": field_unit(topic, n) for topic, _, names, _ in blocks for n in names}
    return {"out_csv": str(out_csv), "rows": len(cells), "columns": columns, "units": units,
            "complete": data.complete}


def _text_column(values: np.ndarray) -> list[str]:
    if values.dtype == np.float32:
        return [str(x) for x in values]  # numpy prints the shortest text that reads back to the same float32
    if values.dtype.kind == "f":
        return [repr(x) for x in values.tolist()]  # shortest text that reads back to the same double
    if values.dtype.kind in "biu":
        return [str(x) for x in values.tolist()]
    return [_text(x) for x in values.tolist()]


def _text(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, (bytes, bytearray)):
        return value.hex()
    if isinstance(value, (list, dict)):
        return json.dumps(value, separators=(",", ":"))
    return str(value)

