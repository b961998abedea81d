"""``python -m zsrm.cli``: the same as the ``zsrm`` command."""
import sys

from zsrm.cli import main

sys.exit(main())
