"""Benchmarks. Each module bench/<name>.py has `run(quick: bool = False) -> dict` returning
figures (medians, ratios, counts) that `python -m bench <name>` and `hil bench` print as JSON.
Timings live here, never as pass/fail thresholds in tests."""

# hil first: it sets OpenBLAS to one thread before numpy loads (hil/__init__.py). Without it,
# a benchmark whose module imports plant_rt (numpy) before hil had an idle BLAS worker spinning
# on the other core, against the loop measured: 1,354 of the plant-only period's 23,834
# instructions under callgrind (bench.period_instructions) were that worker's.
import hil  # noqa: E402,F401
