"""The scene layer: what a scene *is*, how it is read and written, and what is derived from it.

- :mod:`~spacedg.scene.model`: :class:`Scene`, :class:`Instance`, :class:`InstanceVisibility`;
  :mod:`~spacedg.scene.box`: :class:`OrientedBox` (metres, OpenCV camera axes, ``Scene.up``).
- :mod:`~spacedg.scene.io`: every reader and writer; each conversion from another convention
  happens there, once.
- :mod:`~spacedg.scene.synthetic`: the built-in procedural rooms.
- :mod:`~spacedg.scene.visibility`, :mod:`~spacedg.scene.covisibility`: per-view instance
  visibility and view covisibility, from rendered instance ids and depth, cached per scene
  (:mod:`~spacedg.scene.derived_cache`).
- :mod:`~spacedg.scene.store`: the built-in rooms' folder, scene → split assignment, a byte-bounded
  LRU cache; :mod:`~spacedg.scene.floorplan`: top-down pictures; :mod:`~spacedg.scene.language`:
  English wording of labels and descriptions.

This layer imports only :mod:`spacedg.render` and the base modules (``errors``, ``_checks``,
``seeding``, ``files``); it knows nothing of plugins, questions or datasets.
"""

from spacedg.scene.box import OrientedBox
from spacedg.scene.model import Instance, InstanceVisibility, Scene

__all__ = ["Instance", "InstanceVisibility", "OrientedBox", "Scene"]
