"""Procedural indoor rooms, the built-in default scenes (see :mod:`spacedg.data.synthetic.room`)."""

from spacedg.data.synthetic.external import ExternalObject
from spacedg.data.synthetic.room import RoomConfig, generate_room
from spacedg.data.synthetic.trajectory import CaptureConfig

__all__ = ["CaptureConfig", "ExternalObject", "RoomConfig", "generate_room"]
