"""spacedg: degradation-aware spatial QA data rendered online from 3D Gaussian Splatting scenes.

The front door. Core types and conventions (metres; OpenCV camera axes; activated Gaussian
parameters) are documented in :mod:`spacedg.render.gaussians`, :mod:`spacedg.render.camera`
and :mod:`spacedg.scene.model`.

    import spacedg
    scene = spacedg.load_scene("runs/demo/scenes/room-000000")
    dataset = spacedg.SpaceDGDataset("train", ["haze"])   # torch is imported here, on first use
    room = spacedg.generate_room(seed=3)
    scene, report = spacedg.import_scene("output/kitchen", "scenes/kitchen", instances="kitchen.json")  # a real capture
    spacedg.list_degradations(), spacedg.get_question_family("object_counting")
"""

import os as _os

# OpenMP threads that busy-wait after a parallel region (libgomp's default, shared by numba's
# "omp" layer and torch) steal the core from the serial stages between our compiled kernels:
# measured on a 2-vCPU machine, 300 small renders took 4.2 s instead of 0.13 s. Passive
# waiting costs a few microseconds per parallel region. Must be set before libgomp loads,
# i.e. before torch or numba are imported; an explicit user setting wins.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


from spacedg.scene.box import OrientedBox
from spacedg.scene.io import load_scene, save_scene, scene_from_files
from spacedg.scene.model import Instance, InstanceVisibility, Scene
from spacedg.scene.synthetic import ExternalObject, RoomConfig, generate_room
from spacedg.errors import (
    DuplicatePluginError,
    FileFormatError,
    FileValueError,
    InvalidDataError,
    ParameterError,
    PluginError,
    SpaceDGError,
    UnknownPluginError,
)
from spacedg.plugins import (
    get_degradation,
    get_question_family,
    list_degradations,
    list_question_families,
)
from spacedg import render  # the package is callable: spacedg.render(gaussians, camera, ...)
from spacedg.render import Defocus, Frame, MotionBlur, RasterSettings
from spacedg.render.camera import Camera, FisheyeLens
from spacedg.render.gaussians import Gaussians
from spacedg.data.chat import chat_collate

__version__ = "0.1.0"


#: Front-door names imported on first access: name → (module, attribute).
_LAZY = {
    "import_scene": ("spacedg.scene.importer", "import_scene"),
    "assign_instances": ("spacedg.scene.labelling", "assign_instances"),
    "check_frame": ("spacedg.scene.frame_check", "check_frame"),
}


def __getattr__(name: str) -> object:
    """``spacedg.SpaceDGDataset`` on first access: the dataset needs torch, which the rest of the
    front door does not (``import spacedg`` stays light for readers, the renderer and the CLI).
    ``import_scene``, ``assign_instances`` and ``check_frame`` load their modules on first access too."""
    if name in _LAZY:
        import importlib

        module, attribute = _LAZY[name]
        value = getattr(importlib.import_module(module), attribute)
        globals()[name] = value
        return value
    if name == "SpaceDGDataset":
        from spacedg.data.dataset import SpaceDGDataset  # torch: imported on first use

        globals()[name] = SpaceDGDataset
        return SpaceDGDataset
    raise AttributeError(f"module 'spacedg' has no attribute {name!r}")

__all__ = [
    "SpaceDGDataset",
    "assign_instances",
    "check_frame",
    "import_scene",
    "chat_collate",
    "Camera",
    "Defocus",
    "DuplicatePluginError",
    "ExternalObject",
    "FileFormatError",
    "FileValueError",
    "FisheyeLens",
    "Frame",
    "Gaussians",
    "Instance",
    "InstanceVisibility",
    "InvalidDataError",
    "MotionBlur",
    "OrientedBox",
    "ParameterError",
    "PluginError",
    "RasterSettings",
    "RoomConfig",
    "Scene",
    "SpaceDGError",
    "UnknownPluginError",
    "generate_room",
    "get_degradation",
    "get_question_family",
    "list_degradations",
    "list_question_families",
    "load_scene",
    "render",
    "save_scene",
    "scene_from_files",
]
