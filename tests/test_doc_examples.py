"""Every `hil ...` command line and every link string the docs show (README.md and docs/*.md:
fenced code blocks and inline code) is parsed by the CLI's own argparse parser
(hil.cli.main._parser) and the link registry's parser (hil.links.registry.parse_link), so an
example cannot go stale when an option or a link type changes.

A synopsis (a line with [optional] parts, A|B alternatives or "...") shows the form, not a
command, and is not parsed. README.md is being rewritten: while it still holds stale examples
it is an expected failure (strict, so the mark must go when it is fixed)."""
from __future__ import annotations

import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

from hil.cli.main import COMMANDS, _parser
from hil.links.registry import parse_link
from protocol.links import LinkError

REPO = Path(__file__).resolve().parents[1]
DOCS = sorted((REPO / "docs").glob("*.md"))

FENCE = re.compile(r"^```.*?$(.*?)^```", re.M | re.S)
INLINE = re.compile(r"(?<!`)`([^`\n]+)`(?!`)")
COMMAND = re.compile(r"^(?:\$ )?(?:\.venv/bin/)?hil (%s)(?: |$)" % "|".join(COMMANDS))
LINK_IN_YAML = re.compile(r"^\s*link:\s*(\S+)")
# link types a doc declares itself as entry points (its example of a third-party type)
DECLARED_TYPE = re.compile(r'^\[project\.entry-points\."hil\.links"\]\n((?:\w[\w-]* *=.*\n)+)', re.M)
LINK_WORD = re.compile(r"^(?:exec|lib|qemu|serial|can):\S+$")


def _is_synopsis(text: str) -> bool:
    return any(mark in text for mark in ("[", "|", "...", "…"))


def _code_lines(text: str) -> list[tuple[int, str, bool]]:
    """(line number, text, inline) of each line of the fenced blocks (continuations joined)
    and each inline code span."""
    out: list[tuple[int, str, bool]] = []
    for block in FENCE.finditer(text):
        first = text.count("\n", 0, block.start(1)) + 1
        pending, start = "", first
        for offset, line in enumerate(block.group(1).splitlines()):
            if not pending:
                start = first + offset
            if line.rstrip().endswith("\\"):
                pending += line.rstrip()[:-1] + " "
                continue
            out.append((start, pending + line, False))
            pending = ""
    prose = FENCE.sub(lambda m: "\n" * m.group(0).count("\n"), text)
    for span in INLINE.finditer(prose):
        out.append((prose.count("\n", 0, span.start()) + 1, span.group(1), True))
    return out


def _without_comment(line: str) -> str:
    try:
        words = shlex.split(line, comments=True)
    except ValueError:
        return line
    return shlex.join(words)


def problems(path: Path) -> list[str]:
    """What in one file does not parse: 'file:line: text: error'."""
    found = []
    rel = path.relative_to(REPO)
    text = path.read_text(encoding="utf-8")
    declared = tuple(line.split("=")[0].strip() for block in DECLARED_TYPE.finditer(text)
                     for line in block.group(1).splitlines())
    for line_no, raw, inline in _code_lines(text):
        line = raw.strip()
        yaml_link = LINK_IN_YAML.match(line)
        links = [yaml_link.group(1)] if yaml_link else []
        if COMMAND.match(line):
            command = _without_comment(line.removeprefix("$ "))
            if _is_synopsis(command):
                continue
            argv = shlex.split(command)[1:]
            error = io.StringIO()
            try:
                with contextlib.redirect_stderr(error):
                    _parser(argv).parse_args(argv)
            except SystemExit:
                # Prose names a command (`hil run`, `hil log export`) without its arguments.
                # or an option without its value (`hil run --modbus`).
                if inline and ("arguments are required" in error.getvalue()
                               or "expected one argument" in error.getvalue()):
                    continue
                found.append(f"{rel}:{line_no}: `{command}`: the hil CLI refuses it")
                continue
            links += [argv[i + 1] for i, word in enumerate(argv[:-1]) if word == "--link"]
            links += [word.split("=", 1)[1] for word in argv if word.startswith("--link=")]
        elif LINK_WORD.match(line):
            links.append(line)
        for link in links:
            if _is_synopsis(link) or link.isupper():
                continue
            try:
                parse_link(link, declared)
            except LinkError as exc:
                found.append(f"{rel}:{line_no}: link '{link}': {exc}")
    return found


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.name)
def test_doc_examples_parse(path):
    assert problems(path) == []


def _readme_mark():
    stale = problems(REPO / "README.md")
    return [pytest.mark.xfail(strict=True, reason="README.md is being rewritten: "
                              + "; ".join(stale))] if stale else []


@pytest.mark.parametrize("path", [pytest.param(REPO / "README.md", marks=_readme_mark())],
                         ids=["README.md"])
def test_readme_examples_parse(path):
    assert problems(path) == []


def test_a_stale_example_is_caught(tmp_path):
    """The check itself: an unknown option, an unknown link type and a bad link option fail."""
    doc = REPO / "docs" / "_stale_example_test.md"
    doc.write_text("```\nhil run test_plans/ --linx stub\nhil run p.yaml --link exek:./b\n```\n"
                   "Use `hil serve --link exec:./b?argz=1`; in a plan:\n```yaml\nlink: qemu:x.elf?mashine=y\n```\n",
                   encoding="utf-8")
    try:
        found = problems(doc)
    finally:
        doc.unlink()
    assert len(found) == 4, found
    assert "--linx" in found[0] and "exek" in found[1] and "mashine" in found[2] and "argz" in found[3]


def test_examples_that_are_right_pass():
    for link in ("stub", "stub-pty", "qemu", "exec:./b?args=--speed 3&transport=slcan",
                 "lib:./x.so?transport=can", "serial:/dev/ttyUSB0?baud=115200",
                 "can:socketcan:can0?bitrate=1000000", "/dev/ttyACM0", "socket://127.0.0.1:5000"):
        parse_link(link)
    for bad in ("stubb", "exec:./b?transport=can", "serial:/dev/x?baud=fast", "exec:"):
        with pytest.raises(LinkError):
            parse_link(bad)
