import sys

from astrodyn.bench import main

sys.exit(main())
