"""Named colours and materials of the synthetic rooms, and the descriptions built from them.

An :class:`Appearance` (colour name + material) fixes how a surface looks and how an
instance is described: ``"<colour> <material> <label>"`` (e.g. "blue fabric sofa"). It is
view-invariant by construction: it never mentions position or viewpoint.

Colours are display-referred RGB in [0, 1] (what a 3DGS capture stores); bright emitters
(windows) may exceed 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spacedg.scene.language import with_articles

COLOURS: dict[str, tuple[float, float, float]] = {
    "white": (0.90, 0.90, 0.88),
    "light grey": (0.70, 0.70, 0.70),
    "grey": (0.50, 0.50, 0.52),
    "dark grey": (0.27, 0.27, 0.29),
    "black": (0.08, 0.08, 0.09),
    "red": (0.75, 0.13, 0.11),
    "dark red": (0.45, 0.07, 0.08),
    "orange": (0.90, 0.45, 0.10),
    "yellow": (0.92, 0.80, 0.22),
    "green": (0.20, 0.55, 0.25),
    "olive": (0.45, 0.48, 0.20),
    "teal": (0.10, 0.50, 0.50),
    "blue": (0.15, 0.30, 0.75),
    "navy": (0.08, 0.12, 0.35),
    "purple": (0.45, 0.20, 0.55),
    "pink": (0.90, 0.55, 0.65),
    "beige": (0.85, 0.76, 0.60),
    "cream": (0.95, 0.90, 0.78),
    "light brown": (0.70, 0.50, 0.30),
    "brown": (0.45, 0.28, 0.15),
    "dark brown": (0.28, 0.17, 0.09),
}


@dataclass(frozen=True)
class Material:
    """A surface material: the adjective used in descriptions, its texture and the colours it comes in.

    ``sheen`` (0–1) is the strength of the view-dependent highlight written into SH band 1.
    """

    adjective: str
    texture: str
    colours: tuple[str, ...]
    sheen: float = 0.0


MATERIALS: dict[str, Material] = {
    "wood": Material("wooden", "wood", ("light brown", "brown", "dark brown", "beige", "white", "black")),
    "fabric": Material(
        "fabric", "fabric",
        ("red", "blue", "green", "grey", "beige", "navy", "teal", "orange", "purple", "yellow", "pink", "dark grey", "olive"),
    ),
    "leather": Material("leather", "leather", ("black", "brown", "dark brown", "cream", "dark red"), sheen=0.25),
    "metal": Material("metal", "metal", ("grey", "light grey", "black", "white"), sheen=0.45),
    "plastic": Material(
        "plastic", "plastic", ("white", "red", "blue", "green", "yellow", "black", "orange", "teal", "pink", "grey"), sheen=0.2
    ),
    "ceramic": Material("ceramic", "ceramic", ("white", "blue", "teal", "cream", "green", "red", "black", "yellow"), sheen=0.35),
    "cardboard": Material("cardboard", "cardboard", ("brown", "light brown", "beige")),
    "marble": Material("marble", "marble", ("white", "light grey", "black", "beige"), sheen=0.3),
    "hardcover": Material("hardcover", "plastic", ("red", "blue", "green", "black", "yellow", "orange", "navy", "purple", "white")),
    "foliage": Material("leafy", "foliage", ("green", "olive")),
    "screen": Material("screen", "screen", ("black",), sheen=0.5),
}


@dataclass(frozen=True)
class Appearance:
    """A colour on a material."""

    colour: str
    material: str

    @property
    def rgb(self) -> np.ndarray:
        return np.asarray(COLOURS[self.colour], dtype=np.float64)

    @property
    def spec(self) -> Material:
        return MATERIALS[self.material]

    def describe(self, label: str, template: str = "{colour} {material} {label}") -> str:
        """View-invariant description, e.g. ``"blue fabric sofa"`` (``template`` may reorder it;
        "a" becomes "an" before a vowel sound: ``"lamp with an orange fabric shade"``)."""
        return with_articles(template.format(colour=self.colour, material=self.spec.adjective, label=label))


def all_appearances(materials: tuple[str, ...]) -> list[Appearance]:
    """Every (colour, material) combination offered by the given materials, in a fixed order."""
    return [Appearance(c, m) for m in materials for c in MATERIALS[m].colours]


def nearest_colour_name(rgb: np.ndarray) -> str:
    """Name of the palette colour closest to ``rgb`` (used to describe imported objects)."""
    rgb = np.asarray(rgb, dtype=np.float64)
    names = list(COLOURS)
    dist = [float(np.sum((np.asarray(COLOURS[n]) - rgb) ** 2)) for n in names]
    return names[int(np.argmin(dist))]
