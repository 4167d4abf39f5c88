import sys

from edem.cli import console_main

sys.exit(console_main())
