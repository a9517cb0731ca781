"""hil-bench: sessions, clocks, plans, checks, reports, logs and the `hil` command line."""
import os as _os

__version__ = "0.1.0"

# The bench's matrices have a few rows (the EKF design, the sensors' noise blocks): OpenBLAS's
# worker threads never pay here, and after numpy's import-time sanity check (a BLAS dot) its
# idle worker spins on the other core, against a lockstep loop, a pty board or a sweep's other
# worker (two `hil run` side by side with and without it: bench.session.startup_side_by_side,
# README). Only a default: the user's OPENBLAS_NUM_THREADS wins. It is
# read once, when numpy is first imported, so it is set before anything here imports numpy.
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
