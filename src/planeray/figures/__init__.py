"""Paper figures, one function each.

Every function draws on a new :class:`matplotlib.figure.Figure` (built without
pyplot, so importing this package leaves the matplotlib backend alone and no
figure stays open) and returns it; it displays in Jupyter by itself.  Pass
``out=`` to also write the PNG.  Single-panel figures also take ``ax=``, an Axes
to draw into.  More figures: :mod:`planeray.figures.mc` (Monte Carlo profiles)
and :mod:`planeray.figures.study` (the Sec. 5.2 study).
"""

from ._common import display_scale, new_figure, save_image, save_png
from .contact_sheet import contact_sheet_figure
from .labels import label_map_figure
from .profiles import delay_profiles_figure
from .pulse import pulse_methods_figure, pulse_signal_figure, rate_accuracy_figure
from .transport import transport_profiles_figure

__all__ = [
    "display_scale",
    "save_image",
    "new_figure",
    "save_png",
    "contact_sheet_figure",
    "delay_profiles_figure",
    "label_map_figure",
    "pulse_methods_figure",
    "pulse_signal_figure",
    "rate_accuracy_figure",
    "transport_profiles_figure",
]
