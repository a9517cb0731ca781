"""`lib:` loads a private copy of the firmware library per session (fresh globals, nothing
left behind), the stub stays shared, and the link string's options reach the firmware
through the optional hil_fw_configure (protocol/c/hil_fw_abi.h)."""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from protocol.links import LinkError

from hil.links import registry
from hil.links.firmware_library import FirmwareLibraryLink
from hil.links.stub_library import StubLibraryLink

ABI = """
#include <stddef.h>
#include <stdint.h>
#include <string.h>
uint32_t hil_fw_abi_version(void) { return 1u; }
const char *hil_fw_name(void) { return "globals"; }
size_t hil_fw_instance_size(void) { return 0; }
size_t hil_fw_exchange(void *f, const uint8_t *r, size_t n, uint8_t *t, size_t c) { return 0; }
int hil_fw_shutdown_requested(const void *f) { return 0; }
void hil_fw_destroy(void *f) {}
"""

# A microcontroller-style firmware: it boots once per load and relies on the C runtime's
# initialisation of .data (7) and .bss (0); a reused load fails its second create.
GLOBALS = ABI + """
static int data_value = 7;
static int bss_value;
void *hil_fw_create(void *m, size_t n) {
    if (data_value != 7 || bss_value != 0) return NULL;
    data_value = 8; bss_value = 1;
    return &data_value;
}
"""

# Accepts no arguments; refuses any others, its reason the words it got, '|'-separated.
ECHO_ARGS = GLOBALS + """
int hil_fw_configure(void *f, int argc, const char *const *argv, char *why, size_t cap) {
    size_t n = 0;
    if (argv[argc] != NULL) return 9;
    for (int k = 0; k < argc; ++k) {
        if (k && n + 1 < cap) why[n++] = '|';
        for (const char *p = argv[k]; *p && n + 1 < cap; ++p) why[n++] = *p;
    }
    why[n] = 0;
    return argc == 0 ? 0 : 3;
}
"""


def _library(directory: Path, body: str, name: str = "libfw.so") -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    src = directory / "fw.c"
    src.write_text(body)
    out = directory / name
    subprocess.run(["gcc", "-shared", "-fPIC", "-o", str(out), str(src)], check=True)
    return out


def _copies_mapped() -> int:
    """Mappings of private copies (memfd 'hil-fw' or a temporary hil-fw-* directory)."""
    return Path("/proc/self/maps").read_text().count("hil-fw")


def test_each_session_gets_fresh_globals_in_turn_and_at_once(tmp_path):
    lib = _library(tmp_path, GLOBALS)
    first = FirmwareLibraryLink(lib)
    first.close()
    second = FirmwareLibraryLink(lib)            # a reused load would refuse: data_value is 8
    third = FirmwareLibraryLink(lib)             # and two at once have two sets of globals
    assert second._fw != third._fw
    second.close()
    third.close()


def test_a_closed_session_leaves_no_copy_mapped_and_no_descriptor_open(tmp_path):
    lib = _library(tmp_path, GLOBALS)
    fds_before = len(os.listdir("/proc/self/fd"))
    maps_before = _copies_mapped()
    links = [FirmwareLibraryLink(lib) for _ in range(3)]
    assert _copies_mapped() > maps_before
    for link in links:
        link.close()
        link.close()                             # twice is harmless
    assert _copies_mapped() == maps_before
    assert len(os.listdir("/proc/self/fd")) == fds_before
    assert list(tmp_path.iterdir()) == [tmp_path / "fw.c", lib]


def test_a_refused_create_unloads_its_copy(tmp_path):
    lib = _library(tmp_path, ABI + "void *hil_fw_create(void *m, size_t n) { return NULL; }\n")
    maps_before = _copies_mapped()
    with pytest.raises(LinkError, match=r"firmware library '.*libfw.so': hil_fw_create returned NULL"):
        FirmwareLibraryLink(lib)
    assert _copies_mapped() == maps_before


def test_the_stub_shares_one_load_per_process():
    a, b = StubLibraryLink(), StubLibraryLink()
    try:
        assert a._lib is b._lib and not a._image.private
        assert a._fw != b._fw                    # its state is in the instance memory
    finally:
        a.close()
        b.close()
    assert StubLibraryLink()._lib is a._lib       # and it stays loaded


def test_args_reach_hil_fw_configure_split_like_exec(tmp_path):
    lib = _library(tmp_path, ECHO_ARGS)
    query = "--gain%200.5 'two words' plain+word"
    with pytest.raises(LinkError) as err:
        registry.connect(f"lib:{lib}?args={query}")
    text = str(err.value)
    assert f"firmware library '{lib}': hil_fw_configure refused args" in text
    assert "(status 3): --gain|0.5|two words|plain|word" in text
    # exec: splits the same option into the same words
    assert registry._args_option("x", {"args": "--gain 0.5 'two words' plain word"}) == [
        "--gain", "0.5", "two words", "plain", "word"]
    conn = registry.connect(f"lib:{lib}")        # no args: configure sees argc 0 and accepts
    conn.close()


def test_args_for_a_library_without_hil_fw_configure_are_refused_naming_it(tmp_path):
    lib = _library(tmp_path, GLOBALS)
    with pytest.raises(LinkError) as err:
        registry.connect(f"lib:{lib}?args=--verbose")
    assert f"firmware library '{lib}': given args '--verbose'" in str(err.value)
    assert "does not export hil_fw_configure" in str(err.value)
    registry.connect(f"lib:{lib}?args=").close()  # an empty args option is no args


@pytest.mark.parametrize("query, needle", [
    ("arg=1", "unknown option(s) arg (did you mean 'args'?); expected args, transport"),
    ("transprt=can", "unknown option(s) transprt (did you mean 'transport'?)"),
    ("frobnicate=1", "unknown option(s) frobnicate; expected args, transport"),
    ("args=a&args=b", "option(s) args given more than once"),
    ("transport=usb", "transport 'usb'; expected serial or can"),
    ("args='unbalanced", "args: No closing quotation"),
])
def test_bad_lib_options_are_named(tmp_path, query, needle):
    lib = _library(tmp_path, GLOBALS)
    with pytest.raises(LinkError) as err:
        registry.connect(f"lib:{lib}?{query}")
    assert needle in str(err.value)


def test_without_memfd_the_copy_goes_to_a_temporary_file_removed_at_once(tmp_path, monkeypatch):
    import tempfile

    lib = _library(tmp_path / "lib", GLOBALS)
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    monkeypatch.delattr(os, "memfd_create")
    first = FirmwareLibraryLink(lib)
    assert list(scratch.iterdir()) == []          # removed right after dlopen
    second = FirmwareLibraryLink(lib)             # fresh globals all the same
    first.close()
    second.close()
    FirmwareLibraryLink(lib).close()
    assert list(scratch.iterdir()) == []
