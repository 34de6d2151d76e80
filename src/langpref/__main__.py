import sys

from langpref.cli import main

sys.exit(main())
