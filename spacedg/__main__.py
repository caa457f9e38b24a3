import sys

from spacedg.cli import main

sys.exit(main())
