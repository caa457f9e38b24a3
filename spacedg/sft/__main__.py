"""``python -m spacedg.sft +experiment=qwen``: see :mod:`spacedg.sft.app`."""

from spacedg.sft.app import main

if __name__ == "__main__":
    main()
