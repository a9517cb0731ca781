"""Benchmarks. Each module bench/<name>.py has `run(quick: bool = False) -> dict` returning
figures (medians, ratios, counts) that `python -m bench <name>` and `hil bench` print as JSON.
Timings live here, never as pass/fail thresholds in tests."""
