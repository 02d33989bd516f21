# SPDX-License-Identifier: Apache-2.0
"""leadscrew_ros: live prediction of friction-induced squeak in lead-screw drives."""

__version__ = "0.1.0"

__all__ = ["__version__"]      # the layers are sub-packages: model, live, bag, review, ros, cli
