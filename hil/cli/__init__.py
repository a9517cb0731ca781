"""The `hil` command: run, serve, log, bench, plans."""
from hil.cli.main import main

__all__ = ["main"]
