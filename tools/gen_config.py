# SPDX-License-Identifier: Apache-2.0
"""Write config/leadscrew.yaml from the settings' field metadata.

    .venv/bin/python tools/gen_config.py           # rewrites config/leadscrew.yaml
    .venv/bin/python tools/gen_config.py --check   # exit 1 if the file is not current

The text is `leadscrew_ros.ros.parameters.config_yaml()`; test/test_config.py asserts the
shipped file equals it, so a changed default, range or description needs a run of this tool.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from leadscrew_ros.ros.parameters import config_yaml

CONFIG = Path(__file__).resolve().parents[1] / "config" / "leadscrew.yaml"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--check",
        action="store_true",
        help="only compare: exit 1 when the file differs from the generated text",
    )
    args = p.parse_args(argv)
    text = config_yaml()
    if args.check:
        current = CONFIG.read_text() if CONFIG.exists() else ""
        if current != text:
            print(f"{CONFIG} is not current: run tools/gen_config.py", file=sys.stderr)
            return 1
        return 0
    CONFIG.write_text(text)
    print(f"wrote {CONFIG}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
