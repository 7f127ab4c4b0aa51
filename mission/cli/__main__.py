import sys

from mission.cli.main import main

sys.exit(main())
