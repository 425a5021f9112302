import sys

from ipcosim.harness.cli import main

sys.exit(main())
