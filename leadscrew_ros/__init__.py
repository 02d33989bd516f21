"""leadscrew_ros: live prediction of friction-induced squeak in lead-screw drives."""

__version__ = "0.1.0"
