"""The ``hil`` command line.

Exit codes: 0 every plan passed, 1 a plan failed (FAIL or MARGINAL-free FAIL,
TIMEOUT), 2 an error (bad input, the bench or the board failed, ABORTED). A SKIPPED plan
(its link needs a program this machine lacks, e.g. qemu-system-arm; the reason names it)
counts as neither: a run whose plans all passed or were SKIPPED exits 0.
"""
from __future__ import annotations

import argparse
import gc
import os
import sys
from pathlib import Path

# json and hil.links.registry (which brings configfile, yaml, dataclasses, protocol, ctypes) are
# imported by the functions that use them: `hil` imports this module with the cyclic GC on, and
# main() turns it off before anything else is imported (see main).

EXIT_PASS, EXIT_FAIL, EXIT_ERROR = 0, 1, 2
COMMANDS = ("run", "serve", "log", "bench", "plans", "sweep", "init", "probe")
# hil.logs.mcap_writer.COMPRESSIONS, spelt out so that parsing a command line does not import
# the writer (tests/test_cli.py holds the two together)
LOG_COMPRESSIONS = ("lz4", "zstd", "none")
LOG_COMPRESSION_HELP = ("the MCAP log's chunk compression: lz4 (default; its fast mode), zstd "
                        "(smaller files, more time a period) or none (the least time a period, "
                        "the largest files): docs/logging.md")


def _terminal_columns() -> int:
    """shutil.get_terminal_size().columns: $COLUMNS, else the terminal's width, else 80."""
    try:
        columns = int(os.environ["COLUMNS"])
    except (KeyError, ValueError):
        columns = 0
    if columns > 0:
        return columns
    try:
        return os.get_terminal_size(sys.__stdout__.fileno()).columns or 80
    except (AttributeError, ValueError, OSError):
        return 80


class _HelpFormatter(argparse.HelpFormatter):
    """argparse's help formatter, with the width found as argparse finds it but without
    importing shutil for it: argparse makes a formatter for each argument added, and shutil
    imports bz2 and lzma, ~20 M instructions (3 %) of a two-period `hil run`, which uses
    neither."""

    def __init__(self, prog, indent_increment=2, max_help_position=24, width=None):
        super().__init__(prog, indent_increment, max_help_position,
                         _terminal_columns() - 2 if width is None else width)


class _ArgumentParser(argparse.ArgumentParser):
    """An ArgumentParser whose help formatter is _HelpFormatter unless told otherwise; its
    subparsers are of this class too (add_subparsers' default)."""

    def __init__(self, *args, formatter_class=_HelpFormatter, **kwargs):
        super().__init__(*args, formatter_class=formatter_class, **kwargs)


def _parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    parser = _ArgumentParser(
        prog="hil", description="hil-bench: hardware-in-the-loop test bench for motor-controller boards.")
    from hil import __version__

    parser.add_argument("--version", action="version", version=f"hil {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    words = sys.argv[1:] if argv is None else argv
    # A command line that starts with a command is parsed by that command's subparser alone, so
    # only that one is built (each costs its argparse set-up: translations looked up, a help
    # formatter, its arguments). Anything else (hil, hil --help, a misspelt command) builds them
    # all, for the list of commands and the error message.
    only = words[0] if words and words[0] in COMMANDS else None
    from hil.links.registry import LINK_CHOICES

    if only in (None, "run"):
        run = sub.add_parser("run", help="run test plans against a board",
                             description="Run YAML test plans (files, or directories of *.yaml) against a "
                                         "board and write reports and MCAP logs into --out.")
        run.add_argument("plans", nargs="+", type=Path, help="plan files or directories")
        run.add_argument("--link", help=f"board link (default: the plan's, else stub): {', '.join(LINK_CHOICES)}")
        run.add_argument("--mode", choices=("lockstep", "realtime"), help="clock (default: the plan's, else lockstep)")
        run.add_argument("--out", type=Path, default=Path("out"), help="output directory (default: out)")
        run.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
        run.add_argument("--profile", metavar="NAME|PATH",
                         help="run every plan on this bench profile (a name such as paper or "
                              "paper-hardware, or a YAML path) instead of the plans' own profiles")
        run.add_argument("--board", type=Path, metavar="FILE",
                         help="board file: the parameters the board takes and the settings pushed "
                              "to it (default: the plan's `board:`, else the stub's for the stub's "
                              "links, else SPEC's required parameters only; docs/boards.md)")
        run.add_argument("--modbus", metavar="[HOST:]PORT", help="serve the Modbus control port while running")
        run.add_argument("--log-compression", choices=LOG_COMPRESSIONS, default="lz4",
                         help=LOG_COMPRESSION_HELP)
        run.add_argument("--no-progress", action="store_true", help="no progress bar")
        run.add_argument("--live", metavar="[HOST:]PORT", nargs="?", const="127.0.0.1:8765",
                         help="Foxglove WebSocket server while the plans run (default 127.0.0.1:8765)")
        run.add_argument("--live-origin", metavar="ORIGIN", action="append", default=None,
                         help="a web origin allowed to open the live view besides Foxglove's app "
                              "(repeatable; docs/live.md)")

    if only in (None, "serve"):
        serve = sub.add_parser("serve", help="run the plant alone for an external board",
                               description="Run the plant in lockstep against a board until Ctrl-C (or "
                                           "--duration), optionally with the Modbus control port.")
        serve.add_argument("--link", default="stub", help=f"board link: {', '.join(LINK_CHOICES)}")
        serve.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
        serve.add_argument("--profile", type=Path, help="bench profile YAML (default: the paper's)")
        serve.add_argument("--board", type=Path, metavar="FILE",
                           help="board file (default: the stub's for the stub's links, else SPEC's "
                                "required parameters only; docs/boards.md)")
        serve.add_argument("--modbus", metavar="[HOST:]PORT", default="127.0.0.1:5020",
                           help="Modbus TCP control port (default 127.0.0.1:5020; 'off' to disable)")
        serve.add_argument("--duration", type=float, help="simulated seconds to run (default: until Ctrl-C)")
        serve.add_argument("--log", type=Path, help="MCAP log path")
        serve.add_argument("--log-compression", choices=LOG_COMPRESSIONS, default="lz4",
                           help=LOG_COMPRESSION_HELP)
        serve.add_argument("--speed-rpm", type=float, default=0.0,
                           help="speed reference sent to the board (default 0)")
        serve.add_argument("--speed-source", choices=("encoder", "conventional", "ekf"), default="encoder",
                           help="speed feedback the board closes its loop on (default encoder)")
        serve.add_argument("--enable", action="store_true",
                           help="enable the board at start (otherwise: Modbus run bit)")
        serve.add_argument("--live", metavar="[HOST:]PORT", nargs="?", const="127.0.0.1:8765",
                           help="Foxglove WebSocket server for live viewing (default 127.0.0.1:8765)")
        serve.add_argument("--live-origin", metavar="ORIGIN", action="append", default=None,
                           help="a web origin allowed to open the live view besides Foxglove's app "
                                "(repeatable; docs/live.md)")
        serve.add_argument("--live-rate-hz", type=float, default=1000.0,
                           help="rows per second of simulated time sent to viewers (default 1000)")
        serve.add_argument("--pace", choices=("fast", "realtime"), default="fast",
                           help="lockstep as fast as it runs, or paced to the wall clock for a viewer")

    if only in (None, "log"):
        log = sub.add_parser("log", help="inspect an MCAP log", description="Inspect an MCAP log of a run.")
        log_sub = log.add_subparsers(dest="log_command", required=True, metavar="ACTION")
        info = log_sub.add_parser("info", help="channels, message counts, duration, metadata")
        info.add_argument("file", type=Path)
        info.add_argument("--json", action="store_true", help="print JSON")
        plot = log_sub.add_parser("plot", help="PNG plot of signals over a time window")
        plot.add_argument("file", type=Path)
        plot.add_argument("signals", nargs="+", help="e.g. plant.speed_rpm ctrl.speed_ekf_rad_s /plant/truth:i_a")
        plot.add_argument("--out", type=Path, default=Path("plot.png"))
        plot.add_argument("--from", dest="t0", type=float, help="start time, s")
        plot.add_argument("--to", dest="t1", type=float, help="end time, s")
        export = log_sub.add_parser("export", help="CSV export of channels")
        export.add_argument("file", type=Path)
        export.add_argument("channels", nargs="+", help="topics, e.g. /plant/truth")
        export.add_argument("--out", type=Path, default=Path("export.csv"))
        export.add_argument("--from", dest="t0", type=float)
        export.add_argument("--to", dest="t1", type=float)

    if only in (None, "bench"):
        bench = sub.add_parser("bench", help="print every benchmark figure as JSON")
        bench.add_argument("names", nargs="*", help="benchmarks (default all)")
        bench.add_argument("--quick", action="store_true", help="fewer repetitions")

    if only in (None, "plans"):
        plans = sub.add_parser("plans", help="list and validate plans")
        plans.add_argument("paths", nargs="*", type=Path, default=[Path("test_plans")])

    if only in (None, "sweep"):
        sweep = sub.add_parser("sweep", help="run plans many times over a parameter space",
                               description="Run a sweep file (test_plans/sweeps/): its plans over its "
                                           "parameter space, on local processes or a Dask cluster; "
                                           "writes results.parquet/.json, summary.json, index.html and "
                                           "junit.xml into --out (docs/scale.md).")
        sweep.add_argument("sweep", type=Path, help="sweep file")
        where = sweep.add_mutually_exclusive_group()
        where.add_argument("--workers", type=int, default=1, metavar="N",
                           help="local worker processes (default 1)")
        where.add_argument("--cluster", metavar="ADDRESS", help="Dask scheduler, e.g. tcp://HOST:8786")
        sweep.add_argument("--out", type=Path, help="output directory (default out/sweeps/NAME)")
        sweep.add_argument("--resume", action="store_true",
                           help="continue an interrupted sweep in --out without repeating finished runs")
        sweep.add_argument("--no-progress", action="store_true", help="no progress bar")
        sweep.add_argument("--allow-programs", action="store_true",
                           help="run a sweep whose link (exec:, lib:, qemu:) runs a program it names "
                                "(only for sweep files you trust)")

    if only in (None, "init"):
        init = sub.add_parser("init", help="scaffold a bench project for your motor and firmware",
                              description="Write a bench profile from nameplate values, a board file "
                                          "for the stub tuned to the motor, the standard plans that run on "
                                          "any motor and starter plans (limits as formulas of the profile "
                                          "and the board file), CI files and a README (docs/init.md).")
        # init's options come from hil.cli.init (its nameplate dataclass), imported only when the
        # command line can be `hil init ...`: no other command parses them or shows them in --help.
        if "init" in words:
            from hil.cli.init import add_arguments as init_arguments

            init_arguments(init)

    if only in (None, "probe"):
        probe = sub.add_parser("probe", help="measure what the wire to a board allows",
                               description="HELLO, then a train of SAMPLEs against the board: the "
                                           "round trip, the lockstep rate and real-time period it "
                                           "allows, what the port is (sysfs) and the fix when the "
                                           "adapter is slow (docs/adapters.md).")
        from hil.cli.probe import add_arguments as probe_arguments

        probe_arguments(probe)
    return parser


def main(argv: list[str] | None = None) -> int:
    """The ``hil`` program (argv None: sys.argv) or one command run from Python (argv given)."""
    program = argv is None
    if program:
        # The cyclic GC finds next to no garbage among the objects of the modules a command imports
        # (hundreds of thousands: numpy, jsonschema, protobuf, ...), yet walks them in every
        # collection while they are imported and in the full collections of interpreter exit.
        # As a program, `hil` imports with the GC off and freezes what it imported (gc.freeze:
        # later collections skip those objects), and freezes the rest before exiting.
        # 0.1 s of a trivial `hil run`'s 0.6 s. A caller's interpreter (argv given) is left alone.
        gc.disable()
    try:
        return _main(argv, program)
    finally:
        if program:
            gc.freeze()
            gc.enable()


def _imported(program: bool) -> None:
    """The command's modules are imported: freeze them and turn the GC back on (see main)."""
    if program and not gc.isenabled():
        gc.freeze()
        gc.enable()


def _main(argv: list[str] | None, program: bool) -> int:
    args = _parser(argv).parse_args(argv)
    try:
        if args.command == "run":
            from hil.run.runner import run_command

            _imported(program)
            return run_command(args)
        if args.command == "serve":
            from hil.cli.serve import serve_command

            _imported(program)
            return serve_command(args)
        _imported(program)
        if args.command == "log":
            return _log_command(args)
        if args.command == "bench":
            # The benchmarks use the bench, not the other way round: run them as their own
            # program (python -m bench) so hil imports nothing from bench/.
            import subprocess

            argv = [sys.executable, "-m", "bench", *args.names] + (["--quick"] if args.quick else [])
            return subprocess.call(argv)
        if args.command == "plans":
            return _plans_command(args)
        if args.command == "sweep":
            from hil.sweep.run import sweep_command

            return sweep_command(args)
        if args.command == "init":
            from hil.cli.init import init_command

            return init_command(args)
        if args.command == "probe":
            from hil.cli.probe import probe_command

            return probe_command(args)
    except KeyboardInterrupt:
        print("hil: interrupted", file=sys.stderr)
        return EXIT_ERROR
    except Exception as exc:  # noqa: BLE001 - every error leaves with its message and code 2
        from configfile.source import ConfigError

        if isinstance(exc, (ConfigError, OSError, ValueError, RuntimeError)):
            print(f"hil {args.command}: error: {exc}", file=sys.stderr)
            return EXIT_ERROR
        raise
    return EXIT_ERROR


def _log_command(args) -> int:
    import json

    from hil.logs import commands as log_commands

    if args.log_command == "info":
        summary = log_commands.log_info(args.file)
        if args.json:
            print(json.dumps(summary, indent=2, default=str))
        else:
            print(log_commands.format_info(summary))
    elif args.log_command == "plot":
        log_commands.log_plot(args.file, args.signals, args.out, t0=args.t0, t1=args.t1)
        print(f"wrote {args.out}")
    elif args.log_command == "export":
        log_commands.log_export(args.file, args.channels, args.out, t0=args.t0, t1=args.t1)
        print(f"wrote {args.out}")
    return EXIT_PASS


def _plans_command(args) -> int:
    from hil.links.registry import LinkError
    from hil.plans.format import load_plan
    from hil.run.runner import expand_plan_paths, plan_runs, validate_runs
    from configfile.source import ConfigError

    worst = EXIT_PASS
    for path in expand_plan_paths(args.paths):
        try:
            plan = load_plan(path)
            # as `hil run` would run it: each of its profiles with its overrides, the board it
            # runs on by default (its `board:`, else its link's) and its link
            validate_runs(plan_runs([plan]))
        except (ConfigError, LinkError) as exc:
            print(f"INVALID  {exc}")
            worst = EXIT_ERROR
            continue
        print(f"ok       {path}: {plan.name} ({len(plan.steps)} steps) - {plan.description.splitlines()[0] if plan.description else ''}")
    return worst


if __name__ == "__main__":
    raise SystemExit(main())
