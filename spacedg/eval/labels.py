"""Display names of conditions (degradation types) in tables and plots, in the paper's wording."""

from __future__ import annotations

__all__ = ["DEGRADATION_LABELS", "degradation_label"]

#: ``degradation_type`` → column title of the paper's Table 1 (``"ori"`` is the clean image).
DEGRADATION_LABELS: dict[str, str] = {
    "ori": "Clean",
    "defocus": "Defocus",
    "distortion": "Distortion",
    "haze": "Haze",
    "jpeg_compression": "JPEG-com.",
    "low_light": "Low-light",
    "low_res": "Low-res.",
    "motion_blur": "Motion-blur",
    "over_exposure": "Over-exp.",
    "water_droplets": "Water-droplets",
    "avg": "Avg.",
}


def degradation_label(key: str) -> str:
    """The display name of a condition; an unknown one (a third-party degradation or a chain)
    is its key with ``_`` → space, title-cased, parts of a chain joined by ``+``."""
    if key in DEGRADATION_LABELS:
        return DEGRADATION_LABELS[key]
    return "+".join(DEGRADATION_LABELS.get(part, part.replace("_", " ").title()) for part in key.split("+"))
