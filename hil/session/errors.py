"""What ends a session early."""


class SessionError(RuntimeError):
    """The bench or the board failed: the run ends with ERROR and this reason."""
