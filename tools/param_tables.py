# SPDX-License-Identifier: Apache-2.0
"""The README's parameter tables of the node, rendered from the settings' field metadata.

    .venv/bin/python tools/param_tables.py            # prints every table
    .venv/bin/python tools/param_tables.py record     # prints one

One markdown table per entry of `TABLES` (parameter, unit, default, allowed values, meaning);
test/test_settings.py asserts each appears verbatim in README.md, so a changed default, range
or description needs the table pasted again.
"""

from __future__ import annotations

import sys

from leadscrew_ros.bag.recorder import RecordSettings
from leadscrew_ros.live.settings import JointSettings, LiveSettings
from leadscrew_ros.model.physics.metadata import default_text, range_text
from leadscrew_ros.model.uncertainty.scatter import ScatterSettings
from leadscrew_ros.ros.parameters import (GROUPS, READ_ONLY_NOTE, NodeSettings, RecordingControl,
                                          Spec, specs)

# table name -> the settings dataclasses it lists, in the node's parameter order
TABLES = {"node": (LiveSettings, JointSettings, NodeSettings),
          "scatter": (ScatterSettings,),
          "record": (RecordingControl, RecordSettings)}
HEADER = ["| parameter | unit | default | allowed | meaning |", "|---|---|---|---|---|"]


def _cell(text: str) -> str:
    """Markdown table cell text: '|' would end the cell, '<' start an HTML tag."""
    return text.replace("|", "\\|").replace("<", "\\<")


def row(spec: Spec) -> str:
    """One table row of parameter `spec`."""
    md, default = spec.md, spec.default
    shown = f"`{default}`" if isinstance(default, str) and default else default_text(spec.field)
    allowed = (", ".join(f"`{c}`" for c in md["choices"]) if md["choices"] else
               range_text({**md, "unit": ""}) if md["lo"] is not None else "")
    meaning = md["description"] + (f" ({READ_ONLY_NOTE})" if md["read_only"] else "")
    cells = [f"`{spec.name}`", md["unit"], shown, allowed, meaning]
    return "| " + " | ".join(_cell(c) for c in cells) + " |"


def table(name: str) -> str:
    """Markdown table `name` of `TABLES` (no trailing newline)."""
    groups = tuple(g for cls in TABLES[name] for g in GROUPS if g.cls is cls)
    return "\n".join(HEADER + [row(s) for s in specs(groups)])


def main(argv: list[str] | None = None) -> int:
    names = sys.argv[1:] if argv is None else argv
    unknown = set(names) - set(TABLES)
    if unknown:
        print(f"unknown table(s) {', '.join(sorted(unknown))}; known: {', '.join(TABLES)}",
              file=sys.stderr)
        return 2
    print("\n\n".join(table(n) for n in names or TABLES))
    return 0


if __name__ == "__main__":
    sys.exit(main())
