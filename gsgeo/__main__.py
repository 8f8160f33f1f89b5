import sys

from gsgeo.cli import main

sys.exit(main())
