"""``python -m sitframe.cli``: the ``sitframe`` command line."""

import sys

from sitframe.cli.app import console_main

sys.exit(console_main())
