"""One registry of link types: exec:, lib:, qemu:, the stub's names, and third-party entry points."""
from __future__ import annotations

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from plant_rt import load_profile
from protocol.links import LinkError

from hil.links import registry
from hil.links.stub_library import EXECUTABLE_PATH, LIBRARY_PATH, ensure_built
from hil.session.bench_session import BenchSession, SessionConfig, SessionError

REPO = Path(__file__).resolve().parents[1]
SIXSTEP = REPO / "examples" / "sixstep" / "build"


def _run(link: str, periods: int = 300):
    with BenchSession(load_profile(), SessionConfig(link=link, hold_cpu_latency=False)) as session:
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        session.run_periods(periods)
        return session.recorder.arrays(), session.board_name


def test_exec_and_lib_run_the_stub_like_its_own_names():
    ensure_built()
    ref, _ = _run("stub")
    for link in (f"exec:{EXECUTABLE_PATH}?args=--stdio", f"lib:{LIBRARY_PATH}"):
        got, name = _run(link)
        assert name.startswith("hil-stub"), link
        np.testing.assert_array_equal(ref["plant.i_a"][1], got["plant.i_a"][1], err_msg=link)


def test_lib_can_transport_matches_serial():
    ensure_built()
    serial, _ = _run(f"lib:{LIBRARY_PATH}", 200)
    can, _ = _run(f"lib:{LIBRARY_PATH}?transport=can", 200)
    np.testing.assert_array_equal(serial["plant.i_a"][1], can["plant.i_a"][1])


@pytest.mark.skipif(not (SIXSTEP / "sixstep").exists(), reason="examples/sixstep not built")
def test_example_board_through_exec_and_lib():
    a, name_a = _run(f"exec:{SIXSTEP / 'sixstep'}", 400)
    b, name_b = _run(f"lib:{SIXSTEP / 'libsixstep.so'}", 400)
    assert name_a == name_b and "hil-stub" not in name_a
    np.testing.assert_array_equal(a["plant.i_a"][1], b["plant.i_a"][1])


@pytest.mark.skipif(shutil.which("qemu-system-arm") is None, reason="no qemu-system-arm")
def test_qemu_image_link_runs_an_elf():
    elf = SIXSTEP / "sixstep.elf"
    if not elf.exists():
        pytest.skip("examples/sixstep not built")
    got, name = _run(f"qemu:{elf}?machine=mps2-an386", 50)
    assert len(got["plant.i_a"][1]) == 50 and name


def test_exec_board_that_dies_names_its_status_and_stderr(tmp_path):
    board = tmp_path / "broken_board"
    board.write_text("#!/bin/sh\necho 'flash: CRC mismatch at 0x0800' >&2\nexit 3\n")
    board.chmod(0o755)
    with pytest.raises(SessionError) as err:
        with BenchSession(load_profile(), SessionConfig(link=f"exec:{board}", hold_cpu_latency=False)):
            pass
    text = str(err.value)
    assert "exited with status 3" in text and "flash: CRC mismatch at 0x0800" in text


def test_a_board_process_leaves_no_pipe_open_once_its_session_ends():
    """The bench reads the board's stderr to name its last lines on an exit; once the board
    is gone the pipe is closed, not left for the garbage collector (a ResourceWarning)."""
    import gc
    import time
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with BenchSession(load_profile(), SessionConfig(link="stub-pty", hold_cpu_latency=False)) as s:
            s.run_periods(20)
            tail = s.conn._output
        tail()                                   # the reader has seen the end of the pipe
        time.sleep(0.05)
        del s, tail                              # the session's Popen held the pipe
        gc.collect()
    assert [w for w in caught if issubclass(w.category, ResourceWarning)] == []


@pytest.mark.parametrize("spec, needle", [
    ("exec:/nonexistent/board", "executable '/nonexistent/board' does not exist"),
    ("exec:/bin/true?transport=usb", "transport 'usb'; expected serial or slcan"),
    ("exec:/bin/true?baud=9600", "unknown option(s) baud"),
    ("lib:/nonexistent/fw.so", "firmware library '/nonexistent/fw.so': no such file"),
    ("qemu:/nonexistent/fw.elf", "image '/nonexistent/fw.elf' does not exist"),
    ("frob:x", "unknown link 'frob:x'"),
])
def test_bad_link_strings_are_named(spec, needle):
    with pytest.raises(LinkError) as err:
        registry.connect(spec)
    assert needle in str(err.value)


def _library(tmp_path, body: str) -> Path:
    src = tmp_path / "fw.c"
    src.write_text(body)
    out = tmp_path / "libfw.so"
    subprocess.run(["gcc", "-shared", "-fPIC", "-o", str(out), str(src)], check=True)
    return out


def test_lib_refuses_another_abi_version_and_missing_symbols(tmp_path):
    full = """
    #include <stddef.h>
    #include <stdint.h>
    uint32_t hil_fw_abi_version(void) { return VERSION; }
    const char *hil_fw_name(void) { return "x"; }
    size_t hil_fw_instance_size(void) { return 0; }
    void *hil_fw_create(void *m, size_t n) { return (void *)1; }
    size_t hil_fw_exchange(void *f, const uint8_t *r, size_t n, uint8_t *t, size_t c) { return 0; }
    int hil_fw_shutdown_requested(const void *f) { return 0; }
    void hil_fw_destroy(void *f) {}
    """
    v2 = _library(tmp_path, "#define VERSION 2u\n" + full)
    with pytest.raises(LinkError, match=r"firmware ABI version 2, the bench speaks version 1"):
        registry.connect(f"lib:{v2}")
    (tmp_path / "v2").mkdir()
    partial = _library(tmp_path / "v2", "#define VERSION 1u\n" + full.replace(
        "void hil_fw_destroy(void *f) {}", ""))
    with pytest.raises(LinkError, match=r"does not export hil_fw_destroy"):
        registry.connect(f"lib:{partial}")


def test_third_party_link_type_through_the_entry_point_group(tmp_path, monkeypatch):
    """A package that declares `[project.entry-points."hil.links"] loop = ...` adds `loop:`
    without touching the bench (the dist-info here is what pip would install)."""
    pkg = tmp_path / "hil_loop_plugin.py"
    pkg.write_text(textwrap.dedent("""
        from protocol.links import open_link
        def factory(rest, spec):
            return open_link("loop://")
    """))
    dist = tmp_path / "hil_loop_plugin-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: hil-loop-plugin\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[hil.links]\nloop = hil_loop_plugin:factory\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert "loop" in registry.link_types()
    conn = registry.connect("loop:anything")
    try:
        assert conn.link.url.startswith("loop://")
    finally:
        conn.close()
    monkeypatch.undo()
    sys.modules.pop("hil_loop_plugin", None)
    with pytest.raises(LinkError, match="unknown link 'loop:anything'"):
        registry.connect("loop:anything")
