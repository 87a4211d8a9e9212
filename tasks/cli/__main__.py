"""`python -m tasks.cli`: the `bomi` command."""
import sys

from tasks.cli import main

sys.exit(main())
