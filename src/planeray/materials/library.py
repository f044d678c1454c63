"""Recognizing a medium by its fitted parameters: a library of known media.

:mod:`planeray.materials.fit` measures a pixel's (or a region's) reduced scattering
``mu_s'`` and absorption ``mu_a`` with standard errors.  This module names the medium
those numbers belong to, against a **library** of known media.

The library
-----------
A JSON file (:data:`LIBRARY_FORMAT`, version :data:`LIBRARY_VERSION`; written by
:func:`save_library`, read by :func:`load_library`, which refuses a bad file in one line
naming it).  An entry (:class:`MediumEntry`) is **what the fit returns for that medium**
under stated conditions (row size, refractive index, colour channel, calibration) -- not
the medium's published constants: the fit has biases (a shape-only fit's ``mu_a``, the
container walls, ``g`` other than the table's), and a library of published values would
carry them into every decision.  So an entry holds the distribution of the fitted log
parameters over a labelled reference region (its blocks): the geometric mean and the
spread (standard deviation of ``ln mu_s'`` and ``ln mu_a``, their correlation), and the
shares of the region's blocks whose ``mu_s'`` came out **beyond the forward table**
(above it: a medium too strongly scattering for the table, e.g. toothpaste; below it) --
which the fit reports as NaN, not as a number.  The published constants, where known, ride
along (``published``) for the reader.  :func:`entry_from_fit` makes an entry from a fit of a
labelled region of a user's capture ("add from a capture"); :func:`default_library` is the
shipped one (the five Fig. 10 media, fitted on the reference capture of the ``materials``
scene: ``mc/tables/media-library.json``).

Classification
--------------
A fitted pixel ``x = (ln mu_s', ln mu_a)`` with standard errors ``se`` (in log:
``se / estimate``) is scored against each entry by the likelihood of a mixture::

    p(x | entry) = q_above [x above the table] + q_below [x below the table]
                   + (1 - q_above - q_below) N(x; m, S + diag(se^2))

with the entry's mean ``m``, spread ``S`` and shares ``q`` (floored at
:data:`MIN_SHARE`, so no entry is ruled out by one pixel).  The squared Mahalanobis
distance ``d^2 = (x - m)^T (S + diag(se^2))^-1 (x - m)`` decides typicality: the pixel is
**unknown** (class 0) when its best entry's ``d^2`` exceeds the chi-square quantile of
``1 - p_unknown`` (default :data:`DEFAULT_P_UNKNOWN`), i.e. no entry is within the
threshold.  Missing parameters:

* ``mu_a`` NaN (not identifiable -- the common case of a shape-only fit): classified by
  ``mu_s'`` alone (the marginal of the entry's distribution), flagged
  ``MU_S_PRIME_ONLY`` in the result;
* ``mu_s'`` NaN because it lies beyond the table (the fit's reason bit 2, with the side
  from :func:`beyond_table_side`): only the shares ``q`` speak, flagged ``BEYOND_TABLE``;
* ``mu_s'`` NaN for any other reason: unclassified (class 0), flagged ``NOT_FITTED``.

Region-level reasoning
----------------------
Per-pixel fits next to a container wall are biased (the wall takes light the model
attributes to the medium), so a pixel alone may look like another medium.
:func:`pool_log_likelihoods` adds the log-likelihoods of the pixels of a neighbourhood (a
disc of radius ``radius_px``, :func:`scipy.ndimage.uniform_filter`-style) or of a region (a
user's label): the pooled evidence of independent pixels, so a wall pixel is named by its
region's interior.  Which of these works is measured in
:func:`planeray.experiments.materials_recognition.run_recognition_study`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.stats import chi2

from ..errors import InputError

__all__ = [
    "LIBRARY_FORMAT",
    "LIBRARY_VERSION",
    "DEFAULT_P_UNKNOWN",
    "MIN_SHARE",
    "FLAGS",
    "MediumEntry",
    "MediaLibrary",
    "Recognition",
    "beyond_table_side",
    "entry_from_fit",
    "save_library",
    "load_library",
    "default_library",
    "log_likelihoods",
    "classify",
    "pool_log_likelihoods",
    "decide",
]

LIBRARY_FORMAT = "planeray-media-library"
#: Version 2: entries are **physical** parameters -- ``mu_s'``, ``mu_a`` with their uncertainties,
#: the index ``n`` (and a layer's depth) the fit assumed -- valid at any resolution and row size.  Version 1
#: (entries: the distribution of block fits of one capture, bound to its ``conditions``) is still read.
LIBRARY_VERSION = 2
#: Versions this planeray reads.
LIBRARY_VERSIONS = (1, 2)
#: A pixel is unknown when its best entry's typicality p-value is below this.
DEFAULT_P_UNKNOWN = 1e-3
#: Floor of an entry's beyond-table shares and of its in-table share (no entry is ruled out by one pixel).
MIN_SHARE = 0.01
#: Smallest spread (sd of a log parameter) an entry may state: a 1 % spread.
MIN_LOG_SD = 0.01
#: Flags of a classified pixel (bits).
FLAGS = {
    1: "classified by mu_s' alone (mu_a not identifiable)",
    2: "mu_s' beyond the forward table: classified by the entries' beyond-table shares",
    4: "not fitted (mu_s' not identifiable): unclassified",
    8: "unknown: no entry within the threshold",
}
MU_S_PRIME_ONLY, BEYOND_TABLE, NOT_FITTED, UNKNOWN = 1, 2, 4, 8
_SIDES = ("above", "below")


@dataclass(frozen=True)
class MediumEntry:
    """One known medium: the distribution of what the fit returns for it.

    Attributes
    ----------
    name : str
        Its name (unique in a library).
    class_id : int
        The class id its pixels get (1-255; the label images' ids).
    mu_s_prime_per_mm : float or None
        Geometric mean of the fitted ``mu_s'``, mm^-1 (None: always beyond the table).
    mu_s_prime_log_sd : float
        Spread: standard deviation of ``ln mu_s'`` over the reference blocks (>= :data:`MIN_LOG_SD`).
    mu_a_per_mm : float or None
        Geometric mean of the fitted ``mu_a``, mm^-1 (None: not identifiable in the reference).
    mu_a_log_sd : float or None
        Standard deviation of ``ln mu_a`` (None with ``mu_a_per_mm``).
    correlation : float
        Correlation of ``ln mu_s'`` and ``ln mu_a`` over the reference blocks (0 without ``mu_a``).
    beyond_table : dict
        ``{"above": share, "below": share}`` of reference blocks whose ``mu_s'`` lay beyond
        the forward table.
    blocks : int
        Reference blocks the entry was made from.
    source : str
        How it was obtained (capture, region, conditions), free text.
    published : dict or None
        Published constants for the reader (``mu_s_prime_per_mm``, ``mu_a_per_mm``, ``reference``).
    n : float or None
        Refractive index the medium was fitted with (a version-2 entry: the capture is fitted with it to be
        compared with the entry); None in a version-1 library.
    depth_mm : float or None
        Depth of the layer the medium was fitted as (a bottom that returns no light), None: semi-infinite.
    """

    name: str
    class_id: int
    mu_s_prime_per_mm: float | None
    mu_s_prime_log_sd: float
    mu_a_per_mm: float | None = None
    mu_a_log_sd: float | None = None
    correlation: float = 0.0
    beyond_table: dict = field(default_factory=lambda: {"above": 0.0, "below": 0.0})
    blocks: int = 0
    source: str = ""
    published: dict | None = None
    n: float | None = None
    depth_mm: float | None = None

    def shares(self):
        """``(q_above, q_below, q_in)`` with the floors of :data:`MIN_SHARE`, summing to 1."""
        q = np.array([self.beyond_table.get("above", 0.0), self.beyond_table.get("below", 0.0), 0.0])
        q[2] = max(1.0 - q[0] - q[1], 0.0)
        if self.mu_s_prime_per_mm is None:
            q[2] = 0.0
        q = np.maximum(q, MIN_SHARE)
        return q / q.sum()

    def to_json(self) -> dict:
        return {
            "name": self.name,
            "class_id": int(self.class_id),
            "mu_s_prime_per_mm": _num(self.mu_s_prime_per_mm),
            "mu_s_prime_log_sd": float(self.mu_s_prime_log_sd),
            "mu_a_per_mm": _num(self.mu_a_per_mm),
            "mu_a_log_sd": _num(self.mu_a_log_sd),
            "correlation": float(self.correlation),
            "beyond_table": {k: float(self.beyond_table.get(k, 0.0)) for k in _SIDES},
            "blocks": int(self.blocks),
            "source": self.source,
            "published": self.published,
            "n": _num(self.n),
            "depth_mm": _num(self.depth_mm),
        }


@dataclass(frozen=True)
class MediaLibrary:
    """Known media and the conditions their fits were made under.

    Attributes
    ----------
    entries : tuple of MediumEntry
    conditions : dict
        ``mm_per_row`` (mm), ``n``, ``calibrated`` (bool), and free keys (``channel``,
        ``block_px``, ``noise`` ...): a capture classified against a version-1 library should be
        fitted the same way (:meth:`check_conditions`); in version 2, where the reference was
        captured (for the reader).
    version : int
        1: entries are distributions of one capture's block fits (bound to ``conditions``); 2: physical
        parameters with their uncertainties and the ``n`` (depth) they were fitted with
        (:func:`planeray.materials.recognize.entries_from_stack`).
    """

    entries: tuple
    conditions: dict
    version: int = 1

    @property
    def class_ids(self) -> list[int]:
        return [e.class_id for e in self.entries]

    @property
    def physical(self) -> bool:
        """Whether the entries are physical parameters (version 2: valid at any resolution and row size)."""
        return self.version >= 2

    def hypotheses(self) -> list[tuple]:
        """The distinct ``(n, depth_mm)`` the entries were fitted with (a capture is fitted under each)."""
        from .fit import DEFAULT_N

        seen = []
        for e in self.entries:
            h = (DEFAULT_N if e.n is None else float(e.n), e.depth_mm)
            if h not in seen:
                seen.append(h)
        return seen

    def entry(self, name_or_id) -> MediumEntry:
        for e in self.entries:
            if e.name == name_or_id or (isinstance(name_or_id, int) and e.class_id == name_or_id):
                return e
        raise InputError(f"no medium {name_or_id!r} in the library; it has {', '.join(e.name for e in self.entries)}")

    def add(self, entry: MediumEntry, *, replace: bool = False) -> MediaLibrary:
        """A new library with ``entry`` added (or replacing the one of that name with ``replace``)."""
        clash = [e for e in self.entries if e.name == entry.name or e.class_id == entry.class_id]
        if clash and not replace:
            c = clash[0]
            raise InputError(
                f"the library already has {c.name!r} (class {c.class_id}); replace it with --replace (replace=True)"
            )
        keep = tuple(e for e in self.entries if e not in clash)
        return MediaLibrary(keep + (entry,), dict(self.conditions), self.version)

    def check_conditions(self, *, mm_per_row, calibrated) -> None:
        """Refuse (one line) a fit made at another row size or calibration than a version-1 library's
        (a version-2 library holds physical parameters: any capture may be compared with it)."""
        if self.physical:
            return
        lib_mm = self.conditions.get("mm_per_row")
        if lib_mm is not None and not math.isclose(float(lib_mm), float(mm_per_row), rel_tol=1e-3):
            raise InputError(
                f"the library's media were fitted at {lib_mm:g} mm per row, the capture has {float(mm_per_row):g}: "
                "fitted parameters of another row size are not comparable (make a library from such captures)"
            )
        lib_cal = self.conditions.get("calibrated")
        if lib_cal is not None and bool(lib_cal) != bool(calibrated):
            a = "calibrated (white reference)" if lib_cal else "shape-only"
            raise InputError(f"the library holds {a} fits, the capture's fit is not: fit it the same way")

    def to_json(self) -> dict:
        return {
            "format": LIBRARY_FORMAT,
            "version": int(self.version),
            "conditions": dict(self.conditions),
            "media": [e.to_json() for e in self.entries],
        }


def _num(v):
    return None if v is None or not np.isfinite(v) else float(v)


# ---------------------------------------------------------------- making entries
def beyond_table_side(mask, model, *, offsets_rows, mm_per_row, rows_per_camera_row=1.0, table=None) -> np.ndarray:
    """Which side of the forward table a ``mu_s'`` flagged "at the edge" lies on.

    The fit reports such a ``mu_s'`` as NaN (reason bit 2) but keeps its fitted kernel
    (:attr:`~planeray.materials.fit.FitResult.model`).  The side is that of the table's edge
    kernel (largest or smallest ``mu_s'``, middle ``mu_a``) nearer in shape (area-normalized,
    least squares) to the fitted one: above the table the light returns close to the line,
    below it spreads far.

    Parameters
    ----------
    mask : ndarray (P,) uint8
        :attr:`~planeray.materials.fit.FitResult.mask`.
    model : ndarray (P, U)
        :attr:`~planeray.materials.fit.FitResult.model` (the fitted kernels).
    offsets_rows : ndarray (U,)
        Their offsets, projector rows.
    mm_per_row, rows_per_camera_row : float
        The capture's geometry (as for the fit).
    table : ForwardTable, optional
        Default :func:`planeray.materials.fit.forward_table`.

    Returns
    -------
    ndarray (P,) of int8
        +1 above the table, -1 below, 0 not at the edge.
    """
    from . import fit

    table = table or fit.forward_table()
    mask = np.asarray(mask)
    model = np.atleast_2d(np.asarray(model, np.float64))
    h = float(mm_per_row)
    (s0, s1), (a0, a1) = table.bounds_per_row
    a_mid = math.sqrt(a0 * a1) / h
    edges = []
    for s in (s1 * 0.999 / h, s0 * 1.001 / h):
        k = fit.forward_kernel(
            s, a_mid, offsets_rows=offsets_rows, mm_per_row=h, rows_per_camera_row=rows_per_camera_row, table=table
        )
        edges.append(k / k.sum())
    with np.errstate(invalid="ignore", divide="ignore"):
        y = model / np.nansum(model, axis=1, keepdims=True)
    y = np.nan_to_num(y)
    d_hi = ((y - edges[0]) ** 2).sum(axis=1)
    d_lo = ((y - edges[1]) ** 2).sum(axis=1)
    side = np.where(d_hi <= d_lo, 1, -1).astype(np.int8)
    return np.where((mask & 2) > 0, side, 0).astype(np.int8)


#: Fewest blocks (fitted, or beyond the table) an entry is made of: its spread is measured, never assumed.
MIN_ENTRY_BLOCKS = 3


def entry_from_fit(
    mu_s_prime_per_mm,
    mu_a_per_mm,
    side,
    *,
    name: str,
    class_id: int,
    source: str = "",
    published: dict | None = None,
) -> MediumEntry:
    """An entry from the fits of a labelled reference region's blocks (or pixels).

    Parameters
    ----------
    mu_s_prime_per_mm, mu_a_per_mm : array_like (P,)
        Fitted parameters of the region's blocks, mm^-1 (NaN where not identifiable).
    side : array_like (P,) of int
        :func:`beyond_table_side` of each block (+1 above the table, -1 below, 0 inside).
    name, class_id : str, int
        The medium's name and class id (1-255).
    source, published
        Stored with the entry.

    Returns
    -------
    MediumEntry
        Geometric means and log spreads of the identified blocks (``mu_a`` only if at least
        a third of the blocks identify it), the beyond-table shares.
    """
    s = np.asarray(mu_s_prime_per_mm, np.float64).ravel()
    a = np.asarray(mu_a_per_mm, np.float64).ravel()
    side = np.asarray(side).ravel()
    if not (s.size == a.size == side.size) or s.size == 0:
        raise InputError("entry_from_fit needs one mu_s', mu_a and side per block, at least one block")
    if not name or not str(name).strip():
        raise InputError("a medium needs a name")
    if not 1 <= int(class_id) <= 255:
        raise InputError(f"class ids are 1-255, got {class_id}")
    fitted = np.isfinite(s) & (s > 0)
    counted = fitted | (side != 0)
    if not counted.any():
        raise InputError(f"no block of {name!r} was fitted: its mu_s' is not identifiable in this capture")
    if fitted.sum() == 1 or counted.sum() < MIN_ENTRY_BLOCKS:
        raise InputError(
            f"{name!r} has {int(fitted.sum())} fitted block(s) of {s.size}: an entry needs at least "
            f"{MIN_ENTRY_BLOCKS} to measure its spread; label a larger region of it"
        )
    n = int(counted.sum())
    above = float(((side > 0) & ~fitted).sum() / n)
    below = float(((side < 0) & ~fitted).sum() / n)
    ms = sds = None
    if fitted.sum() >= 2:
        ls = np.log(s[fitted])
        ms, sds = float(np.exp(ls.mean())), max(float(ls.std(ddof=1)), MIN_LOG_SD)
    ma = sda = None
    corr = 0.0
    both = fitted & np.isfinite(a) & (a > 0)
    if both.sum() >= max(3, fitted.sum() / 3):
        la, ls2 = np.log(a[both]), np.log(s[both])
        ma, sda = float(np.exp(la.mean())), max(float(la.std(ddof=1)), MIN_LOG_SD)
        if ls2.std() > 0 and la.std() > 0:
            corr = float(np.clip(np.corrcoef(ls2, la)[0, 1], -0.95, 0.95))
    return MediumEntry(
        name=str(name).strip(),
        class_id=int(class_id),
        mu_s_prime_per_mm=ms,
        mu_s_prime_log_sd=float(sds if sds is not None else 0.1),
        mu_a_per_mm=ma,
        mu_a_log_sd=sda,
        correlation=corr,
        beyond_table={"above": above, "below": below},
        blocks=n,
        source=source,
        published=published,
    )


# ---------------------------------------------------------------- the file
def save_library(library: MediaLibrary, path, *, overwrite: bool = True) -> Path:
    """Write ``library`` as JSON, marked as planeray's (``planeray_mark``: "media library"), atomically.

    Callers check that an existing ``path`` may be replaced
    (:func:`planeray.io.atomic.check_replaceable`, kind ``"media library"``) before any work.
    """
    from ..io import atomic_file
    from ..io.marks import MARK_KEY, mark_text

    path = Path(path)
    doc = {MARK_KEY: mark_text("media library"), **library.to_json()}
    with atomic_file(path, overwrite=overwrite) as tmp:
        Path(tmp).write_text(json.dumps(doc, indent=1) + "\n")
    return path


def _bad(path, why):
    return InputError(f"{path}: not a usable media library ({why})")


def _pos(v, path, what, *, allow_none=False):
    if v is None and allow_none:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise _bad(path, f"{what} must be a positive number, got {v!r}")
    return float(v)


def load_library(path) -> MediaLibrary:
    """Read a library written by :func:`save_library` (or by hand, same format).

    Raises
    ------
    InputError
        One line naming the file and what is wrong: unreadable, not JSON, another format or
        version, a missing or non-positive number, a share outside [0, 1], duplicate names
        or class ids, no media.
    """
    path = Path(path)
    try:
        if path.stat().st_size > 16 * 2**20:
            raise _bad(path, "larger than 16 MiB")
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read it ({e.__class__.__name__})") from None
    except (json.JSONDecodeError, RecursionError):
        raise _bad(path, "not JSON") from None
    if not isinstance(doc, dict) or doc.get("format") != LIBRARY_FORMAT:
        raise _bad(path, f"format is not {LIBRARY_FORMAT!r}")
    version = doc.get("version")
    if isinstance(version, bool) or version not in LIBRARY_VERSIONS:
        raise _bad(path, f"version {version!r}, this planeray reads {' and '.join(map(str, LIBRARY_VERSIONS))}")
    cond = doc.get("conditions", {})
    if not isinstance(cond, dict):
        raise _bad(path, "conditions must be an object")
    if "mm_per_row" in cond:
        _pos(cond["mm_per_row"], path, "conditions.mm_per_row")
    media = doc.get("media")
    if not isinstance(media, list) or not media:
        raise _bad(path, "no media")
    entries = []
    for i, m in enumerate(media):
        where = f"media[{i}]"
        if not isinstance(m, dict):
            raise _bad(path, f"{where} is not an object")
        name = m.get("name")
        if not isinstance(name, str) or not name.strip():
            raise _bad(path, f"{where}.name must be a non-empty string")
        cid = m.get("class_id")
        if isinstance(cid, bool) or not isinstance(cid, int) or not 1 <= cid <= 255:
            raise _bad(path, f"{where}.class_id must be an integer 1-255, got {cid!r}")
        bt = m.get("beyond_table", {"above": 0.0, "below": 0.0})
        if not isinstance(bt, dict):
            raise _bad(path, f"{where}.beyond_table must be an object")
        shares = {}
        for k in _SIDES:
            v = bt.get(k, 0.0)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= v <= 1.0:
                raise _bad(path, f"{where}.beyond_table.{k} must be a share in [0, 1], got {v!r}")
            shares[k] = float(v)
        if shares["above"] + shares["below"] > 1.0 + 1e-9:
            raise _bad(path, f"{where}.beyond_table shares add up to more than 1")
        ms = _pos(m.get("mu_s_prime_per_mm"), path, f"{where}.mu_s_prime_per_mm", allow_none=True)
        if ms is None and shares["above"] + shares["below"] <= 0:
            raise _bad(path, f"{where} has neither mu_s_prime_per_mm nor beyond-table shares")
        sds = _pos(m.get("mu_s_prime_log_sd", 0.1), path, f"{where}.mu_s_prime_log_sd")
        ma = _pos(m.get("mu_a_per_mm"), path, f"{where}.mu_a_per_mm", allow_none=True)
        sda = _pos(m.get("mu_a_log_sd"), path, f"{where}.mu_a_log_sd", allow_none=ma is None)
        corr = m.get("correlation", 0.0)
        if isinstance(corr, bool) or not isinstance(corr, (int, float)) or not -1.0 < corr < 1.0:
            raise _bad(path, f"{where}.correlation must be in (-1, 1), got {corr!r}")
        pub = m.get("published")
        if pub is not None and not isinstance(pub, dict):
            raise _bad(path, f"{where}.published must be an object or null")
        blocks = m.get("blocks", 0)
        if isinstance(blocks, bool) or not isinstance(blocks, int) or blocks < 0:
            raise _bad(path, f"{where}.blocks must be an integer >= 0")
        n = _pos(m.get("n"), path, f"{where}.n", allow_none=version == 1)
        if n is not None and not 1.0 <= n <= 2.0:
            raise _bad(path, f"{where}.n must be a refractive index in [1, 2], got {n!r}")
        depth = _pos(m.get("depth_mm"), path, f"{where}.depth_mm", allow_none=True)
        entries.append(
            MediumEntry(
                name=name.strip(),
                class_id=cid,
                mu_s_prime_per_mm=ms,
                mu_s_prime_log_sd=max(sds, MIN_LOG_SD),
                mu_a_per_mm=ma,
                mu_a_log_sd=None if ma is None else max(sda, MIN_LOG_SD),
                correlation=float(corr) if ma is not None else 0.0,
                beyond_table=shares,
                blocks=blocks,
                source=str(m.get("source", "")),
                published=pub,
                n=n,
                depth_mm=depth,
            )
        )
    names = [e.name for e in entries]
    ids = [e.class_id for e in entries]
    if len(set(names)) != len(names):
        raise _bad(path, "two media have the same name")
    if len(set(ids)) != len(ids):
        raise _bad(path, "two media have the same class_id")
    return MediaLibrary(tuple(entries), cond, int(version))


#: The shipped library (the five Fig. 10 media as fitted on the reference capture).
DEFAULT_LIBRARY_PATH = Path(__file__).resolve().parent.parent / "mc" / "tables" / "media-library.json"


def default_library() -> MediaLibrary:
    """The shipped library: the five Fig. 10 media as :mod:`~planeray.materials.fit` returns them.

    Made by :func:`planeray.experiments.materials_recognition.reference_library` on the
    reference capture (the ``materials`` scene, training settings of the report, 128 x 128,
    red channel, Narasimhan et al. 2006 milks, stack demultiplexed, shape-only fits of 2 x 2
    pixel blocks within each tray, every pixel including those next to the walls).  Valid for
    captures fitted the same way (its ``conditions``).
    """
    return load_library(DEFAULT_LIBRARY_PATH)


# ---------------------------------------------------------------- classification
@dataclass(frozen=True)
class Recognition:
    """Per-pixel (or per-region) recognition against a library.

    Attributes
    ----------
    class_ids : ndarray (...) of int
        The best entry's class id; 0 unclassified (not fitted, or unknown).
    log_likelihood : ndarray (..., K)
        ``ln p(x | entry)`` per entry (library order); NaN where not fitted.
    d2 : ndarray (..., K)
        Squared Mahalanobis distance to each entry (NaN for a beyond-table pixel).
    flags : ndarray (...) uint8
        Bits of :data:`FLAGS`.
    classes : list of int
        The entries' class ids (the last axis).
    """

    class_ids: np.ndarray
    log_likelihood: np.ndarray
    d2: np.ndarray
    flags: np.ndarray
    classes: list


def log_likelihoods(
    library: MediaLibrary,
    mu_s_prime_per_mm,
    mu_a_per_mm,
    *,
    mu_s_prime_se_per_mm=None,
    mu_a_se_per_mm=None,
    side=None,
):
    """``ln p(x | entry)`` for every pixel and entry, the Mahalanobis distances and the flags.

    Parameters
    ----------
    library : MediaLibrary
    mu_s_prime_per_mm, mu_a_per_mm : array_like (...)
        Fitted parameters, mm^-1 (NaN where not identifiable).
    mu_s_prime_se_per_mm, mu_a_se_per_mm : array_like (...), optional
        Their standard errors, mm^-1 (default 0: the entries' spreads alone; NaN counts as 0).
    side : array_like (...) of int, optional
        :func:`beyond_table_side` (+1 / -1 where ``mu_s'`` is beyond the table); default: none.

    Returns
    -------
    (log_likelihood (..., K), d2 (..., K), dof (...), flags (...))
        ``dof``: the parameters used (2, 1, or 0 for beyond-table / not fitted).
    """
    s = np.asarray(mu_s_prime_per_mm, np.float64)
    shape = s.shape
    s = s.ravel()
    a = np.broadcast_to(np.asarray(mu_a_per_mm, np.float64), shape).ravel()

    def rel(se, est):
        if se is None:
            return np.zeros(est.size)
        se = np.broadcast_to(np.asarray(se, np.float64), shape).ravel()
        with np.errstate(invalid="ignore", divide="ignore"):
            r = se / est
        return np.where(np.isfinite(r) & (r > 0), r, 0.0)

    rs, ra = rel(mu_s_prime_se_per_mm, s), rel(mu_a_se_per_mm, a)
    sd = np.zeros(s.size, np.int8) if side is None else np.broadcast_to(np.asarray(side), shape).ravel()
    have_s = np.isfinite(s) & (s > 0)
    have_a = have_s & np.isfinite(a) & (a > 0)
    beyond = ~have_s & (sd != 0)
    flags = np.zeros(s.size, np.uint8)
    flags[have_s & ~have_a] |= MU_S_PRIME_ONLY
    flags[beyond] |= BEYOND_TABLE
    flags[~have_s & ~beyond] |= NOT_FITTED
    dof = np.where(have_a, 2, np.where(have_s, 1, 0))
    K = len(library.entries)
    ll = np.full((s.size, K), np.nan)
    d2 = np.full((s.size, K), np.nan)
    xs = np.log(np.where(have_s, s, 1.0))
    xa = np.log(np.where(have_a, a, 1.0))
    for k, e in enumerate(library.entries):
        q_above, q_below, q_in = e.shares()
        lq_in = math.log(q_in)
        if e.mu_s_prime_per_mm is None:  # only ever beyond the table: a pixel inside it is far from it
            ll[have_s, k] = lq_in + _log_normal(np.full(have_s.sum(), 50.0), np.ones(have_s.sum()))
            d2[have_s, k] = np.inf
        else:
            ms, vs = math.log(e.mu_s_prime_per_mm), e.mu_s_prime_log_sd**2
            # one parameter: mu_s' (marginal of the entry)
            m1 = have_s & ~have_a
            v1 = vs + rs[m1] ** 2
            z2 = (xs[m1] - ms) ** 2 / v1
            d2[m1, k] = z2
            ll[m1, k] = lq_in + _log_normal(z2, v1)
            # two parameters
            m2 = have_a
            if e.mu_a_per_mm is None:  # the entry's mu_a unknown: its mu_s' marginal
                v1 = vs + rs[m2] ** 2
                z2 = (xs[m2] - ms) ** 2 / v1
                d2[m2, k] = z2
                ll[m2, k] = lq_in + _log_normal(z2, v1) - 0.5 * math.log(2 * math.pi * 4.0)  # ln N(a) broad
            else:
                ma, va = math.log(e.mu_a_per_mm), e.mu_a_log_sd**2
                c = e.correlation * e.mu_s_prime_log_sd * e.mu_a_log_sd
                v11, v22, v12 = vs + rs[m2] ** 2, va + ra[m2] ** 2, c
                det = v11 * v22 - v12 * v12
                dx, dy = xs[m2] - ms, xa[m2] - ma
                z2 = (v22 * dx * dx - 2 * v12 * dx * dy + v11 * dy * dy) / det
                d2[m2, k] = z2
                ll[m2, k] = lq_in - 0.5 * z2 - 0.5 * np.log((2 * math.pi) ** 2 * det)
        ll[beyond & (sd > 0), k] = math.log(q_above)
        ll[beyond & (sd < 0), k] = math.log(q_below)
    return ll.reshape(*shape, K), d2.reshape(*shape, K), dof.reshape(shape), flags.reshape(shape)


def _log_normal(z2, var):
    return -0.5 * z2 - 0.5 * np.log(2 * math.pi * var)


def decide(library: MediaLibrary, ll, d2, dof, flags, *, p_unknown=DEFAULT_P_UNKNOWN) -> Recognition:
    """Pick the most likely entry; unknown (0) when its typicality p-value is below ``p_unknown``.

    ``ll``, ``d2``, ``dof`` and ``flags`` as :func:`log_likelihoods` returns them (``ll`` may
    be pooled by :func:`pool_log_likelihoods` first; ``d2`` is then the pixel's own).  A
    beyond-table pixel is named by the entries' shares alone and is unknown when the best
    entry's share of its side is below ``p_unknown``.
    """
    if not 0.0 <= float(p_unknown) < 1.0:
        raise InputError(f"p_unknown must be in [0, 1), got {p_unknown!r}")
    ll = np.asarray(ll, np.float64)
    ids = np.asarray(library.class_ids)
    fin = np.isfinite(ll).any(axis=-1)
    best = np.argmax(np.where(np.isfinite(ll), ll, -np.inf), axis=-1)
    out = np.where(fin, ids[best], 0)
    flags = np.array(flags, np.uint8, copy=True)
    if p_unknown > 0:
        d2b = np.take_along_axis(np.asarray(d2, np.float64), best[..., None], axis=-1)[..., 0]
        dof = np.asarray(dof)
        with np.errstate(invalid="ignore"):
            lim = np.where(dof > 0, chi2.isf(p_unknown, np.maximum(dof, 1)), np.inf)
            far = (dof > 0) & ~(d2b <= lim)
        beyond = (flags & BEYOND_TABLE) > 0
        llb = np.take_along_axis(np.where(np.isfinite(ll), ll, -np.inf), best[..., None], axis=-1)[..., 0]
        far |= beyond & (llb < math.log(max(p_unknown, MIN_SHARE)) - 1e-12) & (dof == 0)
        unknown = fin & far
        out = np.where(unknown, 0, out)
        flags[unknown] |= UNKNOWN
    return Recognition(out, ll, np.asarray(d2), flags, list(library.class_ids))


def classify(
    library: MediaLibrary,
    mu_s_prime_per_mm,
    mu_a_per_mm,
    *,
    mu_s_prime_se_per_mm=None,
    mu_a_se_per_mm=None,
    side=None,
    p_unknown=DEFAULT_P_UNKNOWN,
) -> Recognition:
    """Name each pixel's (or region's) medium from its fitted parameters.

    :func:`log_likelihoods` then :func:`decide` (no pooling).  See the module docstring for
    the model; ``flags`` say when ``mu_s'`` alone decided (``mu_a`` NaN), when only the
    beyond-table shares did, and which pixels are unclassified and why.

    Examples
    --------
    >>> lib = MediaLibrary((MediumEntry("a", 1, 1.0, 0.1), MediumEntry("b", 2, 3.0, 0.1)), {})
    >>> classify(lib, [1.1, 2.8, 30.0], [np.nan, np.nan, np.nan]).class_ids.tolist()
    [1, 2, 0]
    """
    ll, d2, dof, flags = log_likelihoods(
        library,
        mu_s_prime_per_mm,
        mu_a_per_mm,
        mu_s_prime_se_per_mm=mu_s_prime_se_per_mm,
        mu_a_se_per_mm=mu_a_se_per_mm,
        side=side,
    )
    return decide(library, ll, d2, dof, flags, p_unknown=p_unknown)


def pool_log_likelihoods(ll, *, radius_px=None, regions=None, valid=None) -> np.ndarray:
    """Pool per-pixel log-likelihoods over a neighbourhood or over regions.

    Parameters
    ----------
    ll : ndarray (H, W, K)
        :func:`log_likelihoods` of an image (NaN where not fitted: contributes nothing).
    radius_px : float, optional
        Sum over a disc of this radius (pixels) around each pixel.
    regions : ndarray (H, W) of int, optional
        Sum over each region (label > 0; pixels of label 0 keep their own).  Exactly one of
        ``radius_px`` and ``regions``.
    valid : ndarray (H, W) bool, optional
        Pixels that contribute (default: those with finite ``ll``).

    Returns
    -------
    ndarray (H, W, K)
        Pooled log-likelihoods (each entry's column minus the pixel-wise maximum is kept
        finite: the argmax is what matters); NaN where no contributing pixel is in reach.
    """
    ll = np.asarray(ll, np.float64)
    if ll.ndim != 3:
        raise InputError(f"pool_log_likelihoods needs (H, W, K) log-likelihoods, got shape {ll.shape}")
    if (radius_px is None) == (regions is None):
        raise InputError("pool over a neighbourhood (radius_px) or over regions, not both or neither")
    fin = np.isfinite(ll).all(axis=-1)
    ok = fin if valid is None else (fin & np.asarray(valid, bool))
    # Each pixel's evidence relative to its own best entry: bounded, so one outlier cannot dominate.
    rel = np.where(
        ok[..., None], ll - np.where(ok, np.nanmax(np.where(fin[..., None], ll, -np.inf), axis=-1), 0.0)[..., None], 0.0
    )
    rel = np.maximum(rel, -20.0)
    if regions is not None:
        reg = np.asarray(regions)
        if reg.shape != ll.shape[:2]:
            raise InputError(f"regions have shape {reg.shape}, the image {ll.shape[:2]}")
        out = np.array(ll, copy=True)
        for r in np.unique(reg[reg > 0]):
            m = reg == r
            tot = rel[m & ok].sum(axis=0)
            if (m & ok).any():
                out[m] = tot
        return out
    r = float(radius_px)
    if not r >= 0:
        raise InputError(f"radius_px must be >= 0, got {radius_px!r}")
    k = int(math.floor(r))
    yy, xx = np.mgrid[-k : k + 1, -k : k + 1]
    disc = (yy * yy + xx * xx <= r * r + 1e-9).astype(np.float64)
    out = np.stack([ndimage.correlate(rel[..., j], disc, mode="constant") for j in range(ll.shape[-1])], axis=-1)
    cnt = ndimage.correlate(ok.astype(np.float64), disc, mode="constant")
    return np.where((cnt > 0)[..., None], out, np.nan)
