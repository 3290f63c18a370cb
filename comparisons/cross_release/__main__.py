"""``python -m comparisons.cross_release``: the study's own command line (see ``study``)."""

import sys

from comparisons.cross_release.study import main

sys.exit(main())
