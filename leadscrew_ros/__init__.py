# SPDX-License-Identifier: Apache-2.0
"""leadscrew_ros: live prediction of friction-induced squeak in lead-screw drives."""


def _version() -> str:
    """The version, written once: in package.xml (setup.py copies it into the metadata).

    A source tree is read first: the package.xml beside this package, if it is ours. This is the
    robust order because the installed metadata can be stale exactly there (an editable install,
    or PYTHONPATH pointing at a checkout, keeps the version of the last `pip install` until the
    next one), while in an installed copy (wheel, colcon) no package.xml sits beside the package
    (it goes to share/leadscrew_ros/), so the metadata, written from package.xml, is read.
    """
    import xml.etree.ElementTree as ET
    from pathlib import Path

    xml = Path(__file__).resolve().parent.parent / "package.xml"
    try:
        root = ET.parse(xml).getroot()
        version_text = root.findtext("version")
        if root.findtext("name") == __name__ and version_text:
            return version_text.strip()
    except (OSError, ET.ParseError):
        pass
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(__name__)
    except PackageNotFoundError:  # neither a source tree nor installed: a copied directory
        return "0+unknown"


__version__ = _version()

__all__ = ["__version__"]  # the layers are sub-packages: model, live, bag, review, ros, cli
