"""Paper figures, one function each (matplotlib, Agg backend, PNG output)."""

from .contact_sheet import contact_sheet_figure
from .labels import label_map_figure
from .profiles import delay_profiles_figure
from .transport import transport_profiles_figure

__all__ = ["contact_sheet_figure", "delay_profiles_figure", "label_map_figure", "transport_profiles_figure"]
