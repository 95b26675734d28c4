import sys

from psyop.cli import main

sys.exit(main())
