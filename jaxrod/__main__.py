"""`python -m jaxrod` runs the command-line interface (see `jaxrod --help`)."""

import sys

from .cli import main


sys.exit(main())
