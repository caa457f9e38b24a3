"""Procedural indoor rooms, the built-in default scenes (see :mod:`spacedg.scene.synthetic.room`)."""

from spacedg.scene.synthetic.external import ExternalObject
from spacedg.scene.synthetic.room import RoomConfig, generate_room
from spacedg.scene.synthetic.trajectory import CaptureConfig

__all__ = ["CaptureConfig", "ExternalObject", "RoomConfig", "generate_room"]
