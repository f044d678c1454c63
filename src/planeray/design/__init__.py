"""Designing the sweep: the few delay-exposure settings that determine the transport best.

The paper captures 85 images on a regular grid chosen by hand (17 delays x 5 exposures) and names
the cost (Sec. 11: "requiring 80-100 images ... not real-time").  Which images a sweep contains is
an experimental-design problem: each image is a row of a known illumination matrix (Eqs. 2-3), the
unknown is a regularized non-negative transport (Eq. 6) and the camera's noise is known.  This
package chooses ``K`` settings among those the camera can realize, minimizing the expected transport
error of the regularized problem for a prior the user picks:

* :mod:`~planeray.design.camera`      :class:`DesignCamera` (noise model, range, steps), from a device or a file
* :mod:`~planeray.design.prior`       :func:`transport_prior` (scenes, transport stores, a smoothness prior)
* :mod:`~planeray.design.candidates`  :func:`candidate_settings` (realizable settings, boundary images left out)
* :mod:`~planeray.design.criterion`   :class:`ExpectedError` (the criterion and its rank-one updates)
* :mod:`~planeray.design.select`      :func:`design_sweep` (greedy, coverage, exchanges), :func:`expected_error`

The result is a :class:`~planeray.timing.Sweep` written as a sweep file
(:func:`planeray.io.write_sweep`), accepted wherever a named sweep is.
"""

from .camera import DesignCamera, camera_from_device, camera_from_file
from .candidates import DEFAULT_EXPOSURE_RANGE_US, Candidates, band_rows, candidate_settings
from .criterion import CRITERIA, ExpectedError
from .prior import PRIOR_ALL_SCENES, PRIOR_SMOOTH, TransportPrior, transport_prior
from .select import SweepDesign, design_sweep, expected_error, image_variance

__all__ = [
    "CRITERIA",
    "DEFAULT_EXPOSURE_RANGE_US",
    "PRIOR_ALL_SCENES",
    "PRIOR_SMOOTH",
    "Candidates",
    "DesignCamera",
    "ExpectedError",
    "SweepDesign",
    "TransportPrior",
    "band_rows",
    "camera_from_device",
    "camera_from_file",
    "candidate_settings",
    "design_sweep",
    "expected_error",
    "image_variance",
    "transport_prior",
]
