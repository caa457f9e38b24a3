"""Built-in degradations, one module per degradation.

Each module defines ``SPEC`` (a :class:`~spacedg.plugins.specs.DegradationSpec`), a plain
function doing the work (e.g. :func:`~spacedg.plugins.degradations.jpeg_compression.jpeg_compress`),
and the hook ``spacedg_register_degradations``
(:func:`~spacedg.plugins.hookspecs.registering`); it is announced as an entry point of the
``spacedg`` distribution in ``pyproject.toml``, exactly as a third-party plugin would be.
Modules are imported by the registry, not here. Shared, not plugins:
:mod:`~spacedg.plugins.degradations.common` (input checks, stream keys, far depth),
:mod:`~spacedg.plugins.degradations._sensor` (the sensor model) and
:mod:`~spacedg.plugins.degradations._exposure` (``low_light`` and ``over_exposure`` made from
their data).
"""
