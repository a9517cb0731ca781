"""Instructions a lockstep period costs, counted by valgrind's callgrind: repeatable where the
timings of bench.session drift 10-30 % on this VM, and split by where they go.

For `stub`, `stub` with the full MCAP log, and the plant alone (sample, truth, step replaying
the stub's switch words), each the difference of two runs of bench._period_worker that differ
only in the number of periods (start-up, handshake and warm-up cancel). The logged period is
then split into the C functions that do its work, by their inclusive counts:

- ``exchange``: SAMPLE encoded, handed to the stub and its answers decoded, in C (the period
  loop and exchange_sample share: exchange_frames in protocol/c/python/_hilcodec.c), of which
  ``firmware`` is the stub itself (hil_fw_exchange: its decoder, control law and encoder);
- ``answer_objects``: the TELEMETRY message objects the recorder keeps (message_object);
- ``plant_kernel``: the plant's C sample, truth and RK4 (plant_rt/c/_plantnet.c);
- ``lz4`` and ``crc32``: the MCAP chunks' compression and checksums (ISA-L's CRC for the
  chunks, zlib's for the small records: hil.logs.mcap_writer.crc32);
- ``python_and_objects``: the rest: the interpreter running the period loop, the plant's and
  recorder's Python, object allocation, the MCAP writer's Python.

``stub``, ``stub+log`` and ``plant_only`` also run with callgrind's cache and branch models
(``simulated_misses_per_period``: misses of a first-level instruction cache, ``I1``, and data
cache, ``D1_read`` and ``D1_write``, of this CPU's sizes; ``simulated_mispredicts_per_period``:
conditional and indirect branches its simple predictors miss; models, not the CPU's counters,
which this VM does not expose). Their instruction counts are the same as without them; the
misses are the instructions' cost that a count does not show: the bench's C code and the
firmware's add code and tables to every period that the plant's loop alone does not touch.

Since the C period loop (protocol.ccodec.exchange_periods) the last is mostly the plant's
Python (sample, truth, step) and the MCAP writer's.
``stub+log, lz4 level 0`` is the logged period with the chunks compressed at the lz4
library's default level instead of the writer's (hil.logs.mcap_writer.LZ4_LEVEL);
``stub+log, records packed by numpy`` without the C codec's records_into (the log's records
built column by column), and ``stub+log, the Python period loop`` with every period in
BenchSession's Python loop instead of the C one: what each of the two C pieces saves.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

#: part name -> C functions whose inclusive counts it sums
PARTS = {
    "exchange": ("exchange_frames",),
    "firmware": ("hil_fw_exchange",),
    "answer_objects": ("message_object",),
    "plant_kernel": ("mod_sample", "mod_truth", "mod_advance"),
    "lz4": ("LZ4_compress_fast_continue",),
    "crc32": ("crc32_z", "isal_zlib_crc32"),   # zlib's below 16 KiB, ISA-L's for the chunks
}


def _inclusive(out_file: Path) -> dict[str, int]:
    """Function name -> inclusive instructions (its largest entry: callgrind_annotate also
    lists inlined header lines under the same name)."""
    text = subprocess.run(["callgrind_annotate", "--inclusive=yes", "--threshold=100", "--show=Ir",
                           str(out_file)],
                          capture_output=True, text=True, check=True).stdout
    found: dict[str, int] = {}
    for line in text.splitlines():
        m = re.match(r"\s*([\d,]+) \([\s\d.]+%\)\s+\S*:(\w+) \[", line)
        if m is not None and "=>" not in line:
            count = int(m.group(1).replace(",", ""))
            found[m.group(2)] = max(found.get(m.group(2), 0), count)
    return found


#: callgrind's events with --cache-sim=yes --branch-sim=yes, in the order of its "Collected :"
#: line: instructions, data reads and writes, the misses of its cache model (first level I1/D1,
#: last level LL), then conditional and indirect branches and those its predictors missed.
CACHE_EVENTS = ("Ir", "Dr", "Dw", "I1mr", "D1mr", "D1mw", "ILmr", "DLmr", "DLmw",
                "Bc", "Bcm", "Bi", "Bim")


def _run(kind: str, periods: int, out_file: Path, cache: bool = False) -> list[int]:
    """Runs bench._period_worker under callgrind; its "Collected" events: [instructions], or
    all of CACHE_EVENTS with `cache` (the cache and branch models do not change the instruction
    count)."""
    env = dict(os.environ, PYTHONHASHSEED="0")
    proc = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out_file}",
                           *(["--cache-sim=yes", "--branch-sim=yes"] if cache else []),
                           sys.executable, "-m", "bench._period_worker", kind, str(periods)],
                          capture_output=True, text=True, cwd=REPO, env=env)
    m = re.search(r"Collected :((?: \d+)+)", proc.stderr)
    if proc.returncode != 0 or m is None:
        raise RuntimeError(f"bench._period_worker {kind} {periods} under callgrind failed:\n"
                           f"{proc.stderr[-800:]}")
    return [int(v) for v in m.group(1).split()]


def per_period(kind: str, periods: int, split: bool = False, cache: bool = False) -> dict:
    """Instructions a period of `kind`; with `split` its parts (PARTS), with `cache` the
    misses a period in callgrind's cache model (first-level instruction and data caches of
    this CPU's sizes, 32 KiB each here: ``I1``, ``D1_read``, ``D1_write``; ``last_level``) and
    the branches its predictors miss a period (``conditional``, ``indirect``)."""
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(2) as pool:
        short, long = Path(tmp) / "short.out", Path(tmp) / "long.out"
        # the two runs side by side: instruction counts do not depend on the machine's load
        runs = (pool.submit(_run, kind, periods, long, cache),
                pool.submit(_run, kind, 0, short, cache))
        events = [(b - a) / periods for a, b in zip(runs[1].result(), runs[0].result())]
        total = events[0]
        out = {"instructions_per_period": round(total)}
        if cache:
            ev = dict(zip(CACHE_EVENTS, events))
            out["simulated_misses_per_period"] = {
                "I1": round(ev["I1mr"]), "D1_read": round(ev["D1mr"]),
                "D1_write": round(ev["D1mw"]),
                "last_level": round(ev["ILmr"] + ev["DLmr"] + ev["DLmw"], 1)}
            out["simulated_mispredicts_per_period"] = {
                "conditional": round(ev["Bcm"]), "indirect": round(ev["Bim"])}
        if split:
            a, b = _inclusive(short), _inclusive(long)
            parts = {name: round(sum(b.get(f, 0) - a.get(f, 0) for f in funcs) / periods)
                     for name, funcs in PARTS.items()}
            top = ("exchange", "answer_objects", "plant_kernel", "lz4", "crc32")
            parts["python_and_objects"] = round(total - sum(parts[p] for p in top))
            out["parts"] = parts
    return out


def run(quick: bool = False) -> dict:
    if shutil.which("valgrind") is None or shutil.which("callgrind_annotate") is None:
        return {"error": "valgrind (callgrind) is not installed"}
    # Long enough that the garbage collector's full passes (every so many surviving objects)
    # average out: 1000 periods read 76,000 instructions for `stub` once, 4000 read 53,800.
    periods = 2000 if quick else 4000
    # The three headline kinds run with callgrind's cache and branch models as well: the
    # instruction counts are the same, and the misses show where the wall ratio departs from
    # the instruction one.
    out = {"periods": periods, "stub": per_period("stub", periods, cache=True),
           "stub+log": per_period("stub+log", periods, split=True, cache=True),
           "stub+log, lz4 level 0": per_period("stub+log@lz4_level0", periods, split=True),
           "stub+log, records packed by numpy": per_period("stub+log@numpy_packing", periods),
           "stub+log, the Python period loop": per_period("stub+log@python_loop", periods),
           "plant_only": per_period("plant", periods, cache=True)}
    out["stub+log_vs_plant_only"] = round(out["stub+log"]["instructions_per_period"]
                                          / out["plant_only"]["instructions_per_period"], 2)
    return out
