"""Python's cyclic garbage collector paused around allocation-heavy pure-Python work.

Why: building a room's question index allocates hundreds of thousands of small containers
(candidates, their closures, selection entries) that live until the room is done, next to a
scene whose visibility tables hold many more. Every few hundred allocations the cyclic
collector wakes up, and as the pool grows it keeps scanning all of them again: on the built-in
rooms that was about a quarter of question generation's time, while a whole build frees only a
few dozen cycles. Reference counting frees everything else as before, so pausing the collector
changes no result, only when cyclic garbage (there is almost none) is reclaimed.

The pause is scoped (:func:`collector_paused`): the collector's state is restored on exit,
also on an exception, and an inner pause inside an outer one leaves the outer one's state alone.
Where it is used: a scene's question generation without a judge
(:func:`~spacedg.qa.build.generate_records`; a judge renders views and may call a model, whose
garbage should not wait for the scene's end) and reading a question index
(:func:`~spacedg.qa.index.read_index`).
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator

__all__ = ["collector_paused"]


@contextlib.contextmanager
def collector_paused() -> Iterator[None]:
    """Within this block the cyclic collector does not run on its own (``gc.disable``); on exit it
    runs again if it was running on entry. Process-wide, like the collector itself: another
    thread's allocations are not collected during the block either."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()
