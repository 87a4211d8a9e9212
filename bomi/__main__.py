import sys

from bomi.cli import main

sys.exit(main())
