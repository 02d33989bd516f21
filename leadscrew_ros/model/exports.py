# SPDX-License-Identifier: Apache-2.0
"""Package names resolved on first use: a layer's package init exports its classes without
importing every module (a replay's worker, the config docs and the CLI load what they use)."""

from __future__ import annotations

from collections.abc import Callable
from importlib import import_module
from typing import Any


def lazy(package: str, homes: dict[str, str]) -> Callable[[str], Any]:
    """The module `__getattr__` of `package` that imports each name of `homes` (name -> the
    module of the package that defines it) when it is first asked for.

    Parameters
    ----------
    package : str
        The package's `__name__`.
    homes : dict of str to str
        Exported name -> its module, relative to the package.

    Returns
    -------
    callable
        The package's `__getattr__`.
    """

    def __getattr__(name: str) -> Any:
        if name in homes:
            return getattr(import_module(f".{homes[name]}", package), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
