# ruff: noqa: I001 - the order is the documentation's: groups of the front door, then the pipeline
# The front door's one list: what ``import planeray as pr`` holds. planeray/__init__.py reads it
# (lazy loading, ``__all__``, ``dir``) and type checkers and IDEs read it as the package's stub.
# Each name is re-exported as ``X as X``; add a name here and it is public, loaded when first used.

__version__: str

# imaging model (Eqs. 1-6)
from .timing import PAPER_LINES_PER_SECOND as PAPER_LINES_PER_SECOND
from .timing import PAPER_PROJECTOR_ROWS as PAPER_PROJECTOR_ROWS
from .timing import Band as Band
from .timing import RowPattern as RowPattern
from .timing import RowGeometry as RowGeometry
from .timing import Sweep as Sweep
from .timing import paper_sweep as paper_sweep
from .timing import quick_sweep as quick_sweep
from .timing import make_sweep as make_sweep
from .transport import Transport as Transport
from .transport import SparseEntries as SparseEntries

# captures
from .stack import Stack as Stack
from .camera import CameraModel as CameraModel
from .scenes import make_scene as make_scene
from .scenes import list_scenes as list_scenes
from .scenes.skin import skin_veins as skin_veins
from .devices import SimulatedEpiscan as SimulatedEpiscan
from .devices import ReplayDevice as ReplayDevice
from .acquire import simulate_stack as simulate_stack
from .acquire import acquire_sweep as acquire_sweep
from .acquire import acquire_to_store as acquire_to_store
from .calibration import calibrate_lines_per_second as calibrate_lines_per_second
from .calibration import calibrate_delay_zero as calibrate_delay_zero

# files
from .io import read_stack as read_stack
from .io import write_stack as write_stack
from .io import import_folder as import_folder
from .io import export_folder as export_folder
from .io import read_transport as read_transport
from .io import write_transport as write_transport

# demultiplexing (Sec. 4)
from .demux import DemuxProblem as DemuxProblem
from .demux import demultiplex as demultiplex
from .demux import demultiplex_to_store as demultiplex_to_store

# analysis (Secs. 4, 7, 8, 9)
from .synthesis import epipolar_image as epipolar_image
from .synthesis import non_epipolar_image as non_epipolar_image
from .synthesis import sharpened_epipolar as sharpened_epipolar
from .synthesis import band_image as band_image
from .synthesis import relight as relight
from .synthesis import short_long_range as short_long_range
from .profiles import measured_delay_profiles as measured_delay_profiles
from .profiles import transport_delay_profiles as transport_delay_profiles
from .classify import classify_transport as classify_transport

# subsurface scattering (Sec. 5.2)
from .medium import Medium as Medium
from .mc import mc_line_profile as mc_line_profile
from .kernels import line_kernel as line_kernel

# any Mitsuba 3 scene -> transport
from .render import render_transport as render_transport

# every public module and subpackage, down the pipeline (tests/test_front_door.py checks that none is missing)
from . import errors as errors
from . import goodness as goodness
from . import timing as timing
from . import medium as medium
from . import optical_data as optical_data
from . import optical_data_skin as optical_data_skin
from . import linesweep as linesweep
from . import transport as transport
from . import stack as stack
from . import camera as camera
from . import io as io
from . import resumable as resumable
from . import calibration as calibration
from . import mc as mc
from . import kernels as kernels
from . import render as render
from . import scenes as scenes
from . import projector as projector
from . import devices as devices
from . import acquire as acquire
from . import rig as rig
from . import demux as demux
from . import design as design
from . import synthesis as synthesis
from . import profiles as profiles
from . import classify as classify
from . import materials as materials
from . import baselines as baselines
from . import skin as skin
from . import pulse as pulse
from . import live as live
from . import study as study
from . import figures as figures
from . import experiments as experiments
from . import viewer as viewer
from . import demo as demo
from . import cli as cli
