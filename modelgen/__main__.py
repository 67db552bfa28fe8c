"""``python -m modelgen`` runs the command line (see :mod:`modelgen.cli`)."""
import sys

from modelgen.cli import main

sys.exit(main())
