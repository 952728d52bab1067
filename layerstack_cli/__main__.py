"""``python -m layerstack_cli``."""

import sys

from . import main

sys.exit(main())
