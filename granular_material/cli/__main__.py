"""``python -m granular_material.cli``: the command line."""

import sys

from granular_material.cli import main

sys.exit(main())
