"""Watching a run live: the log's full-rate channels over the Foxglove WebSocket protocol
(foxglove-sdk's server), decimated for the viewer, and commands a viewer may publish.

Names are imported on first use, so that the gate's own process (hil.live.gate, spawned)
does not import the stream, the SDK and the session."""

__all__ = ["LiveStream", "parse_live_address"]


def __getattr__(name: str):
    if name in __all__:
        from hil.live import stream

        return getattr(stream, name)
    raise AttributeError(f"module 'hil.live' has no attribute {name!r}")
