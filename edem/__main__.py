import sys

from edem.cli import main

sys.exit(main())
