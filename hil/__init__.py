"""hil-bench: sessions, clocks, plans, checks, reports, logs and the `hil` command line."""

__version__ = "0.1.0"
