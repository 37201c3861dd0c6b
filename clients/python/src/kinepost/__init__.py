"""A client for kinepost's HTTP API, for CAM plug-ins: post CL data and stream the NC, run
large programs as jobs with progress, and ask a machine's kinematics (FK, IK).

Every post reports an :class:`Outcome`; a program is fit to run only when ``outcome.ok``.
"""

from ._client import CL, Client
from ._streams import RecordStream, TextStream
from ._types import Job, JobProgress, KinepostError, Outcome, Pose, Program

__all__ = [
    "CL",
    "Client",
    "Job",
    "JobProgress",
    "KinepostError",
    "Outcome",
    "Pose",
    "Program",
    "RecordStream",
    "TextStream",
]
__version__ = "0.1.0"
