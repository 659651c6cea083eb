import sys

from pris_cosim.cli import main

sys.exit(main())
