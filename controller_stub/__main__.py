"""`python -m controller_stub serve ...` (same as the `controller-stub` script)."""

import sys

from controller_stub.cli import main

sys.exit(main())
