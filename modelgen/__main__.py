"""``python -m modelgen`` runs the command line (see :mod:`modelgen.cli`)."""
from modelgen.cli import run

run()
