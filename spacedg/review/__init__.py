"""Benchmark review: a local web page (``spacedg review``) over a :class:`ReviewStore`."""

from spacedg.review.store import ReviewError, ReviewStore

__all__ = ["ReviewError", "ReviewStore"]
