"""Sessions: the period loop between the plant and a board, its two clocks (lockstep and
real time) sharing one watchdog and one answer wait, the CPU-latency hold, the link tap
(raw-frame capture and link faults) and the parameters pushed to the board."""
from hil.session.bench_session import BenchSession, CommandState, SessionConfig
from hil.session.errors import SessionError

__all__ = ["BenchSession", "CommandState", "SessionConfig", "SessionError"]
