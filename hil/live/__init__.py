"""Watching a run live: the log's full-rate channels over the Foxglove WebSocket protocol
(foxglove-sdk's server), decimated for the viewer, and commands a viewer may publish."""
from hil.live.stream import LiveStream, parse_live_address

__all__ = ["LiveStream", "parse_live_address"]
