"""The ``spacedg`` subcommands, one module each (``add_parser`` + ``run``).

Import policy: a subcommand module imports the library it drives inside ``run`` (not at module
level), so ``spacedg --help`` and a mistyped flag answer without loading the renderer, numba,
torch or the question index of every other subcommand. Library modules below this layer import
at module level; their remaining function-level imports are the heavy ones (numba kernels,
torch, transformers, cv2), each marked where it is made.
"""
