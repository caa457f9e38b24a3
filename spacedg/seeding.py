"""Seeds: every random choice in spacedg flows from an explicit seed through :func:`derive_seed`.

``derive_seed(seed, *keys)`` hashes the seed and the keys (their ``str``) with SHA-256, so the
same arguments give the same 63-bit seed in every process, worker and machine; feed it to
``numpy.random.default_rng`` (or ``torch.Generator().manual_seed``). Global random state is
never used.
"""

from __future__ import annotations

import hashlib

__all__ = ["derive_seed"]


def derive_seed(seed: int, *keys: object) -> int:
    """A 63-bit seed from ``seed`` and ``keys`` (SHA-256 based: the same in every process)."""
    text = ":".join([str(int(seed)), *(str(k) for k in keys)])
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "little") >> 1
