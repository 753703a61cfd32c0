"""``python -m sitframe``: the ``sitframe`` command line (as ``python -m sitframe.cli``)."""

import sys

from sitframe.cli.app import console_main

sys.exit(console_main())
