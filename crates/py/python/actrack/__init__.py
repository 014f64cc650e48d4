"""actrack: track a human arm in video by tracking the action it performs.

numpy in, numpy out. The classes and functions are implemented in Rust (``actrack._actrack``);
this package re-exports them.

Errors: invalid input raises :class:`ActrackError` (a ``ValueError``); a file that cannot be read
or written raises :class:`ActrackOSError` (an ``OSError``). Both carry the Rust message.
"""

from ._actrack import (
    ActionModel,
    ActrackError,
    ActrackOSError,
    Estimate,
    FitReport,
    Hmm,
    Phmm,
    Scene,
    ThetaEstimate,
    Tracker,
    __version__,
    centred_median,
    contour_likelihood,
    edge_image,
    evaluate,
    load_mocap,
    track_video,
)

__all__ = [
    "ActionModel",
    "ActrackError",
    "ActrackOSError",
    "Estimate",
    "FitReport",
    "Hmm",
    "Phmm",
    "Scene",
    "ThetaEstimate",
    "Tracker",
    "__version__",
    "centred_median",
    "contour_likelihood",
    "edge_image",
    "evaluate",
    "load_mocap",
    "track_video",
]
