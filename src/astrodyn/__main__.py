import sys

from astrodyn.cli import main

sys.exit(main())
