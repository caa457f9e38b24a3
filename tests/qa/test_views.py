"""The qa layer's clean view (judge, preview) is the sample pipeline's clean image, byte for byte."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.data.pipeline import PipelineOptions, degrade
from spacedg.errors import ParameterError
from spacedg.qa.views import render_clean_view


def test_clean_view_equals_the_pipelines_clean_image(small_room) -> None:
    view = sorted(small_room.views)[0]
    ours = render_clean_view(small_room, view, (64, 48), backend="cpu")
    theirs = degrade(small_room, [view], None, options=PipelineOptions(image_size=(64, 48), backend="cpu")).images[0]
    assert ours.dtype == np.uint8 and ours.shape == (48, 64, 3)
    assert np.array_equal(ours, theirs)


def test_clean_view_refuses_a_size_beyond_the_policy(small_room) -> None:
    with pytest.raises(ParameterError, match="image_size"):
        render_clean_view(small_room, sorted(small_room.views)[0], (100_000, 10))
