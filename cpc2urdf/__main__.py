import sys

from cpc2urdf.cli import main

sys.exit(main())
