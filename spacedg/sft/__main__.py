"""``python -m spacedg.sft +experiment=qwen``: see :mod:`spacedg.sft.command` (the entry point) and :mod:`spacedg.sft.app` (the run)."""

from spacedg.sft.command import main

if __name__ == "__main__":
    main()
