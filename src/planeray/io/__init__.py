"""Reading and writing stacks, captured image folders and transports (public API of ``planeray.io``).

Three on-disk formats are handled here, one module each (:mod:`~planeray.io.stack_store`,
:mod:`~planeray.io.folder`, :mod:`~planeray.io.transport_store`; single image files in
:mod:`~planeray.io.images`, atomic writes in :mod:`~planeray.io.atomic`).  All writers are atomic: they write into a
temporary sibling (``.{name}.tmp-{uuid}`` in the same parent folder) and rename it
into place, so a crash or an error never leaves a half-written result at the
target path (see :func:`atomic_directory` and :func:`atomic_file`).

Native stack store
------------------
A Zarr v3 directory store (group) written by :func:`write_stack`, read by
:func:`read_stack`:

=================  ==========  =======  ==========================================
array              shape       dtype    content
=================  ==========  =======  ==========================================
``images``         (N, H, W)   float32  normalized images, chunked ``(1, 32, W)``
``saturated``      (N, H, W)   bool     saturation mask (all False if unknown)
``delay_us``       (N,)        float64  delay ``t_d`` of each image
``exposure_us``    (N,)        float64  exposure ``t_e`` of each image
``excluded``       (N,)        bool     images left out of demultiplexing
=================  ==========  =======  ==========================================

Group attributes: ``format = "planeray-stack"``, ``format_version = 1``,
``lines_per_second`` (float), ``projector_rows`` (int), ``metadata`` (the
:attr:`planeray.stack.Stack.metadata` dict, JSON), ``planeray_version`` and
optional ``all_chunks_stored`` (see *Complete chunks* below).

Captured-stack import folder (public format)
--------------------------------------------
A folder read by :func:`import_folder` (and by :func:`read_stack` when the folder
holds a ``manifest.csv``), written by :func:`export_folder`::

    my_capture/
        manifest.csv
        acquisition.json
        img_0000.tif            (or .tiff / .png; any names, listed in the manifest)
        ...

``manifest.csv``
    Comma-separated, UTF-8, one header line, one line per image.  Required columns
    ``file,delay_us,exposure_us``; ``file`` is the image path relative to the
    folder, ``delay_us`` the delay ``t_d`` and ``exposure_us`` the exposure ``t_e``
    in microseconds (finite numbers, exposure > 0).  Optional column ``excluded``
    (``0``/``1``/``true``/``false``, case-insensitive) marks images left out of
    demultiplexing; without it the paper's boundary rule
    ``||t_d| - t_e/2| <= 75 us`` is applied
    (:func:`planeray.timing.boundary_images`).  Other columns are ignored.  An
    image, or a (``delay_us``, ``exposure_us``) setting, listed on two lines is
    refused, naming both line numbers (planeray does not average repeated
    captures).

images
    Single-channel (grayscale) 2-D images, all of the same size and pixel type
    (dtype; the first image that differs from the first one is named, with both
    types): 8- or 16-bit integer TIFF (``.tif``/``.tiff``) or PNG (``.png``), or
    float32/float64 TIFF.  Integer values are raw ADC codes and must not exceed
    ``2**bit_depth - 1``; an integer type that cannot hold ``bit_depth`` is
    refused (8-bit images need ``"bit_depth": 8``, also when ``bit_depth`` is
    absent).  Float images are refused unless ``float_images`` says what they
    hold, and must not contain NaN.

``acquisition.json``
    A JSON object with

    * ``lines_per_second`` (required, positive number): projector scanline
      velocity ``v_p`` (Eq. 2);
    * ``bit_depth`` (integer 1..16, default 12): ADC bit depth;
    * ``black_level`` (number >= 0 and < ``2**bit_depth - 1``, default 0): raw code
      of black;
    * ``projector_rows`` (integer, optional): projector rows spanned by the image
      height (default: the image height);
    * ``saturation_level`` (number, optional): raw code at or above which a pixel
      counts as saturated (default ``2**bit_depth - 1``);
    * ``float_images`` (``"raw"`` or ``"normalized"``, only with float TIFFs):
      ``"raw"``: the values are raw ADC codes, normalized like integer codes;
      ``"normalized"``: they are already ``(raw - black_level) / (2**bit_depth -
      1 - black_level)`` and are taken as they are (``bit_depth`` and
      ``black_level`` are not applied; ``saturation_level`` is then in the same
      units, in (0, 1], default 1);
    * ``planeray_metadata`` (object, optional): written by :func:`export_folder`;
      restored as the stack's metadata on import;
    * any other field, kept verbatim.

    Images are normalized as ``(raw - black_level) / (2**bit_depth - 1 -
    black_level)`` (float32) and a pixel is flagged saturated where ``raw >=
    saturation_level``.  The imported stack's metadata is ``planeray_metadata`` (if
    any) plus ``metadata["acquisition"]`` (the JSON object without
    ``planeray_metadata``) and ``metadata["source"] = "import:<folder>"``.

Transport store (public format)
-------------------------------
A Zarr v3 group written by :func:`write_transport`, read by :func:`read_transport`:
array ``T`` of shape ``(H, W, U)`` float32 (the dense band of
:class:`planeray.transport.Transport`) and attributes ``offsets_rows`` (the ``U``
consecutive integer offsets ``u = v - t``, in projector rows), ``lines_per_second``
(or null), ``projector_rows``, ``format = "planeray-transport"``,
``format_version = 1``, plus free-form attributes (``alpha``, ``beta``,
``method``...).  Sparse long-range entries, when there are any, are stored as the
1-D arrays ``sparse_row``, ``sparse_col``, ``sparse_offset`` (int32) and
``sparse_value`` (float32) of equal length.  Offset ``u`` is the bin
``[u - 1/2, u + 1/2)`` of ``u = v - p_t`` (``p_t = (t + 1/2) P / H - 1/2``), and
``T`` holds the light of the part of that bin on the projector,
``[-1/2, P - 1/2)``: the binning and edge rules of
:meth:`planeray.timing.RowGeometry.row_bins` and :meth:`~planeray.timing.RowGeometry.bin_parts`.

Sweep file (public format)
--------------------------
A small JSON file naming the images of a sweep (``delay_us``, ``exposure_us``, optional
``excluded``, ``name`` and ``record``), read by :func:`read_sweep` and written by
:func:`write_sweep`; see :mod:`planeray.io.sweep_file`.

Complete chunks (both stores)
-----------------------------
Writers store every chunk, also those equal to the fill value, and mark the
group ``all_chunks_stored = true``; readers then refuse a store with an absent
chunk file, naming the array and the chunk (zarr would read it as zeros).
Stores without the attribute (earlier planeray versions skipped chunks equal to
the fill value) are read as before.  New arrays use zstd with its content
checksum; a chunk that cannot be read or decoded raises one
:class:`~planeray.errors.StackError` / :class:`~planeray.errors.TransportError`
naming the store, the array, the chunk and the cause.  Writers that fill a
store of their own use :func:`create_array` and :func:`writable`.
"""

from ._common import (
    FORMAT_VERSION,
    STACK_FORMAT,
    TRANSPORT_FORMAT,
    LazyArray,
    create_array,
    jsonable,
    planeray_version,
    store_format,
    writable,
)
from .atomic import atomic_directory, atomic_file
from .folder import export_folder, import_folder
from .images import write_image
from .stack_store import create_stack_group, read_stack, validate_images, write_stack
from .sweep_file import SWEEP_FORMAT, read_sweep, write_sweep
from .transport_store import read_transport, read_transport_maps, transport_attrs, write_transport

__all__ = [
    "STACK_FORMAT",
    "SWEEP_FORMAT",
    "read_sweep",
    "write_sweep",
    "TRANSPORT_FORMAT",
    "FORMAT_VERSION",
    "LazyArray",
    "jsonable",
    "planeray_version",
    "store_format",
    "create_array",
    "writable",
    "atomic_directory",
    "atomic_file",
    "write_stack",
    "create_stack_group",
    "read_stack",
    "validate_images",
    "import_folder",
    "export_folder",
    "write_image",
    "write_transport",
    "read_transport",
    "read_transport_maps",
    "transport_attrs",
]
