"""Hydra configs of ``python -m spacedg.sft`` (importable as ``spacedg.conf`` so that an installed
wheel finds them with ``pkg://spacedg.conf``). See ``sft.yaml``."""
