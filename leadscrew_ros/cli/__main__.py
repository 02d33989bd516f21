# SPDX-License-Identifier: Apache-2.0
"""`python -m leadscrew_ros.cli`: the `leadscrew-squeak` command."""

import sys

from . import main

if __name__ == "__main__":
    sys.exit(main())
