"""The errors that mean bad input from the user: exit status 2 with a one-line reason."""

from __future__ import annotations

from models.avatars.checkpoint import CheckpointError
from models.capture.dataset import DatasetError
from models.device import DeviceError
from models.head.controls import ControlsError
from models.head.model import HeadModelError
from models.ranges import OptionError
from models.tracking.canonical import BundleError
from models.tracking.fit import FitError
from models.tracking.pipeline import TrackingError
from models.tracking.video import VideoError


class UserInputError(ValueError):
    """Bad arguments or a bad input file; the message names the file and the problem."""


#: Exceptions that are the user's input being wrong, not the program failing.
INPUT_ERRORS = (UserInputError, HeadModelError, ControlsError, DatasetError, CheckpointError, DeviceError,
                BundleError, VideoError, OptionError, FitError, TrackingError)
