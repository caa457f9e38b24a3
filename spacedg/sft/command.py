"""``spacedg-sft`` / ``python -m spacedg.sft``: the Hydra entry point, light until a run starts.

Hydra composes the config and answers ``--cfg job``, ``--help``, ``--info`` and a malformed override
before the app function runs, so this module imports only Hydra: torch, transformers and peft (5–7 s
of imports on a CPU machine) are imported by :mod:`spacedg.sft.app` when training starts. A resolved
config is then a second's work (``python -m spacedg.sft +experiment=paper --cfg job``).
"""

from __future__ import annotations

import os
import sys
from typing import Any

import hydra

from spacedg.errors import SpaceDGError

__all__ = ["main"]


def main() -> None:
    """Console entry point (``spacedg-sft`` and ``python -m spacedg.sft``): compose ``conf/sft.yaml``
    with the command line's overrides and train (:func:`spacedg.sft.app.run`); a spacedg error is
    one line on stderr and exit code 2."""

    @hydra.main(version_base="1.3", config_path="pkg://spacedg.conf", config_name="sft")
    def _app(cfg: Any) -> None:
        from spacedg.sft.app import run, shut_down_process_group

        try:
            run(cfg)
        except SpaceDGError as err:  # one clear line, as the spacedg CLI prints it (Hydra would print a traceback)
            print(f"spacedg-sft: error: {err}", file=sys.stderr)
            raise SystemExit(2) from None
        shut_down_process_group()

    os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")
    _app()
