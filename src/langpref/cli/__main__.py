"""`python -m langpref.cli ...`, as the `langpref` command."""

import sys

from langpref.cli import main

sys.exit(main())
