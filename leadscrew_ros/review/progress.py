# SPDX-License-Identifier: Apache-2.0
"""Progress bars on stderr (tqdm) for the command-line tools.

`disable=None` lets tqdm switch itself off when stderr is not a terminal, so piped or captured
output (tests, CI logs, `2> file`) stays clean.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from tqdm import tqdm


@contextmanager
def progress_bar(
    total: int | None, desc: str, unit: str = "pt", leave: bool = False
) -> Iterator[Callable[[int], None]]:
    """A tqdm bar on stderr (a counter when `total` is None: unknown); yields its
    `update(n_done)` callable (the model's `progress=`)."""
    with tqdm(
        total=total,
        desc=desc,
        unit=unit,
        leave=leave,
        disable=None,
        file=sys.stderr,
        dynamic_ncols=True,
    ) as bar:
        yield bar.update
