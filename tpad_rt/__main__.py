"""``python -m tpad_rt`` runs the ``tpad-rt`` command line."""

import sys

from tpad_rt.cli import main

sys.exit(main())
