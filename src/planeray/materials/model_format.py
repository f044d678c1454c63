"""A material model and its file: the trained classifier with its feature definition, saved without pickle.

:class:`MaterialModel` (what :func:`planeray.materials.model.train_model` returns) segments
captures (:class:`Segmentation`; the typicality test of unclassified pixels); :meth:`MaterialModel.save`
writes it and :func:`load_model` reads it back, bounding every member before reading it (the
format is described in :mod:`planeray.materials.model`).
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._validate import check_number
from ..errors import InputError
from ..io import atomic_file, jsonable
from ..io.atomic import ALREADY_EXISTS
from ..stack import Stack
from .capture import capture_features
from .features import FeatureDefinition

MODEL_FORMAT = "planeray-materials-model"


#: 2: the record carries its own SHA-256 (``record_sha256``) and the typicality model.
MODEL_FORMAT_VERSION = 2


_META = "planeray-model.json"


_BLOB = "model.skops"


#: Largest JSON record read (bytes, uncompressed; a model's record is ~0.1-1 MB).
MAX_RECORD_BYTES = 16 * 2**20


#: Largest estimator read (bytes, uncompressed): 256 MiB, ~30x the support vectors of
#: 20 captures x 6 classes x 400 pixels of 1000 features each.
MAX_ESTIMATOR_BYTES = 256 * 2**20


#: Deepest nesting of the JSON record and of the skops schema (a model's: < 15).
MAX_JSON_DEPTH = 64


#: Default of ``unclassified_below`` (``materials predict --unclassified-below``): a pixel
#: less typical of the SVM's pick than 99 % of that class's held-out training pixels is
#: unclassified.  Measured on held-out captures of the report's scene at 128x128 (README):
#: 0.3-0.9 % of the SVM's right picks are lost, 3-24 % of its wrong ones and all of a table
#: left out of training are flagged; 0.05 flags every wrong pick but loses 2.4-5.8 %.
DEFAULT_UNCLASSIFIED_BELOW = 0.01


#: Principal components of the typicality model.
TYPICALITY_COMPONENTS = 6


#: Every type a saved model may contain, as ``module.Class``: the pipeline and its two
#: steps, and the plain containers and NumPy values their fitted state is made of.
#: :func:`load_model` refuses a file with any other type before building anything.
ALLOWED_TYPES = (
    "sklearn.pipeline.Pipeline",
    "sklearn.preprocessing._data.StandardScaler",
    "sklearn.svm._classes.SVC",
    "builtins.dict",
    "builtins.list",
    "builtins.tuple",
    "builtins.str",
    "builtins.int",
    "builtins.float",
    "builtins.bool",
    "builtins.NoneType",
    "numpy.ndarray",
    "numpy.dtype",
    "numpy.float64",
    "numpy.float32",
    "numpy.int64",
    "numpy.int32",
)


@dataclass
class Segmentation:
    """A segmented capture: the SVM's pick per pixel, how typical the pixel is of it, and the result.

    Attributes
    ----------
    labels : ndarray (H, W) int64
        Class ids; 0 where a pixel has no usable profile or is unclassified.
    svm_labels : ndarray (H, W) int64
        The SVM's pick (0 only where a pixel has no usable profile).
    typicality : ndarray (H, W) float64
        Conformal p-value of the pick (module docstring); NaN without a profile.
    no_profile : ndarray (H, W) bool
        Pixels without light to classify.
    unclassified : ndarray (H, W) bool
        Pixels with a profile whose typicality is below ``unclassified_below``.
    unclassified_below : float
        The threshold used (0: none unclassified).
    """

    labels: np.ndarray
    svm_labels: np.ndarray
    typicality: np.ndarray
    no_profile: np.ndarray
    unclassified: np.ndarray
    unclassified_below: float


def check_unclassified_below(value) -> float:
    """``unclassified_below`` in ``[0, 1)`` (0 keeps every pick of the SVM)."""
    return check_number(value, "unclassified_below", minimum=0.0, maximum=1.0, max_inclusive=False)


@dataclass
class MaterialModel:
    """A trained per-pixel material classifier and the definition of its features.

    Attributes
    ----------
    pipeline : sklearn.pipeline.Pipeline
        ``StandardScaler`` then ``SVC(kernel="rbf")``.
    definition : FeatureDefinition
        What the features are (:func:`~planeray.materials.features.stack_features`).
    classes : dict of int to str
        Class ids the model predicts and their names.
    training : dict
        How it was trained: captures, pixels per class, cross-validation grid and scores,
        chosen ``C`` and ``gamma``.
    typicality : dict
        The typicality model (module docstring): ``components`` (K, F) and ``mean`` (F)
        of the principal components of the standardized training features,
        ``area_center`` and ``area_scale`` of the log area, and per class id ``center``
        (K + 1), ``precision`` (K + 1, K + 1) and ``calibration`` (sorted squared
        distances of held-out training pixels).

    See Also
    --------
    train_model : trains one.
    load_model : reads a saved one.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 8, Fig. 10.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> scene = pr.make_scene("wax", (8, 8), seed=0)  # a wax object (label 2) on a plane (label 1)
    >>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
    >>> from planeray.materials import train_model
    >>> model = train_model(
    ...     [stack],
    ...     [scene.labels],
    ...     class_names={1: "plane", 2: "wax"},
    ...     param_grid={"C": (10.0,), "gamma_scale": (1.0,)},
    ...     cv_folds=2,
    ... )
    >>> type(model).__name__, model.classes
    ('MaterialModel', {1: 'plane', 2: 'wax'})
    >>> float((model.predict(stack) == scene.labels).mean())
    1.0
    """

    pipeline: object
    definition: FeatureDefinition
    classes: dict
    training: dict = field(default_factory=dict, repr=False)
    typicality: dict = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------ prediction
    def predict_features(self, features) -> np.ndarray:
        """The SVM's class ids of feature rows ``(P, F)`` (no typicality check)."""
        X = self._features(features)
        return self.pipeline.predict(X).astype(np.int64)

    def _features(self, features) -> np.ndarray:
        X = np.asarray(features, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != self.definition.n_features:
            raise InputError(f"expected features of shape (P, {self.definition.n_features}), got {X.shape}")
        return X

    def typicality_of(self, features, class_ids, area) -> np.ndarray:
        """Conformal p-value of each pixel as one of ``class_ids`` (module docstring), in ``(0, 1]``.

        ``features``: rows ``(P, F)``; ``area``: the area of each pixel's profiles before
        normalization (``signal`` of :func:`capture_features`, > 0).
        """
        X = self._features(features)
        cids = np.asarray(class_ids, dtype=np.int64)
        p = np.ones(X.shape[0])
        if not self.typicality:
            return p
        proj = _typicality_space(self.typicality, self.pipeline.steps[0][1].transform(X), area)
        for cid, entry in self.typicality["classes"].items():
            sel = cids == int(cid)
            if not sel.any():
                continue
            d = _mahalanobis2(proj[sel], entry["center"], entry["precision"])
            cal = np.asarray(entry["calibration"], dtype=np.float64)
            p[sel] = (1.0 + cal.size - np.searchsorted(cal, d, side="left")) / (cal.size + 1.0)
        return p

    def smallest_typicality(self) -> dict:
        """Per class id, the smallest typicality a pixel can get, ``1 / (n + 1)`` (``n`` held-out training pixels).

        A threshold at or below it unclassifies none of the class's pixels.
        """
        return {
            int(cid): 1.0 / (np.asarray(entry["calibration"]).size + 1.0)
            for cid, entry in (self.typicality.get("classes") or {}).items()
        }

    def check_stack(self, stack: Stack, *, source=None) -> None:
        """Refuse, before any work, a stack whose features the model cannot read (another sweep, line rate)."""
        from .features import stack_definition

        if self.definition.kind == "stack":
            self.definition.check(stack_definition(stack, floor=self.definition.floor), source=source)
        elif not np.isclose(stack.lines_per_second, self.definition.lines_per_second, rtol=1e-6, atol=0):
            raise InputError(
                f"the model was trained on {self.definition.describe()}; this sweep runs at "
                f"{stack.lines_per_second:g} lines/s",
                source,
            )

    def segment(
        self,
        stack: Stack,
        *,
        unclassified_below: float = DEFAULT_UNCLASSIFIED_BELOW,
        transport=None,
        source=None,
        progress=None,
    ) -> Segmentation:
        """Segment a stack: the SVM's pick per pixel, its typicality, and the pixels left unclassified.

        Parameters
        ----------
        stack : Stack
            Captured with the sweep the model was trained on (else :class:`InputError`).
        unclassified_below : float
            A pixel whose typicality (conformal p-value of the SVM's pick, module
            docstring) is below this is unclassified (id 0); 0: keep every pick.
        transport : Transport, optional
            For a transport model: the stack's transport if already demultiplexed with
            the model's options (:func:`capture_transport`); otherwise it is demultiplexed here.
        source : str, optional
            Name of the stack in error messages.
        progress : callable, optional
            Demultiplexing progress (rows).
        """
        threshold = check_unclassified_below(unclassified_below)
        X, signal, _ = capture_features(
            stack, definition=self.definition, transport=transport, source=source, progress=progress
        )
        svm = np.zeros(signal.shape, np.int64)
        typical = np.full(signal.shape, np.nan)
        ok = signal.ravel() > 0
        if ok.any():
            picks = self.predict_features(X[ok])
            svm.ravel()[ok] = picks
            typical.ravel()[ok] = self.typicality_of(X[ok], picks, signal.ravel()[ok])
        unclassified = ok.reshape(signal.shape) & (typical < threshold)
        return Segmentation(
            labels=np.where(unclassified, 0, svm),
            svm_labels=svm,
            typicality=typical,
            no_profile=~ok.reshape(signal.shape),
            unclassified=unclassified,
            unclassified_below=threshold,
        )

    def predict(
        self,
        stack: Stack,
        *,
        unclassified_below: float = DEFAULT_UNCLASSIFIED_BELOW,
        transport=None,
        source=None,
        progress=None,
    ) -> np.ndarray:
        """Per-pixel class ids ``(H, W)`` of a stack: 0 where a pixel has no usable profile or is unclassified.

        ``unclassified_below=0`` gives the SVM's pick for every pixel with a profile (the
        paper's classifier); see :meth:`segment` for the parameters.
        """
        return self.segment(
            stack, unclassified_below=unclassified_below, transport=transport, source=source, progress=progress
        ).labels

    # ------------------------------------------------------------ storage
    def record(self) -> dict:
        """The JSON record saved beside the estimator (without the digests)."""
        import sklearn
        import skops

        from ..io import planeray_version

        return {
            "format": MODEL_FORMAT,
            "format_version": MODEL_FORMAT_VERSION,
            "definition": self.definition.to_dict(),
            "classes": {str(k): v for k, v in self.classes.items()},
            "training": self.training,
            "typicality": self.typicality,
            "planeray_version": planeray_version(),
            "sklearn_version": sklearn.__version__,
            "skops_version": skops.__version__,
        }

    def save(self, path, *, overwrite: bool = False) -> Path:
        """Write the model (zip: JSON record + skops estimator), atomically; no pickle.

        An existing file is replaced only with ``overwrite`` and only if it is a planeray
        model itself.  The record holds the SHA-256 of the estimator and, under
        ``record_sha256``, that of itself (every other field, canonical JSON): any edit of
        either member is refused by :func:`load_model`.
        """
        import skops.io as sio

        path = Path(path)
        check_model_output(path, overwrite=overwrite)
        blob = sio.dumps(self.pipeline)
        meta = jsonable({**self.record(), "estimator_sha256": hashlib.sha256(blob).hexdigest()})
        meta["record_sha256"] = record_digest(meta)
        with atomic_file(path, overwrite=True) as tmp:
            with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as z:
                z.writestr(_META, json.dumps(meta, indent=1, sort_keys=True))
                z.writestr(_BLOB, blob)
        return path


def _typicality_space(model: dict, Z, area) -> np.ndarray:
    """Coordinates of the typicality model: principal components of ``Z``, then the standardized log area."""
    comp = np.asarray(model["components"], dtype=np.float64)
    proj = (np.asarray(Z, dtype=np.float64) - np.asarray(model["mean"], dtype=np.float64)) @ comp.T
    log_area = np.log(np.maximum(np.asarray(area, dtype=np.float64), 1e-300))
    return np.column_stack([proj, (log_area - model["area_center"]) / model["area_scale"]])


def _mahalanobis2(points, center, precision) -> np.ndarray:
    d = np.asarray(points, dtype=np.float64) - np.asarray(center, dtype=np.float64)
    return np.einsum("ij,jk,ik->i", d, np.asarray(precision, dtype=np.float64), d)


def record_digest(meta: dict) -> str:
    """SHA-256 of a model record: canonical JSON (sorted keys, no spaces) of every field but ``record_sha256``."""
    body = {k: v for k, v in meta.items() if k != "record_sha256"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def check_model_output(path, *, overwrite: bool) -> None:
    """Refuse a model output that exists (without ``overwrite``) or that is not a planeray model."""
    path = Path(path)
    if path.suffix.lower() != ".zip":
        raise InputError("a model file must end in .zip (a zip of a JSON record and a skops estimator)", path)
    if path.exists() or path.is_symlink():
        if not overwrite:
            raise InputError(ALREADY_EXISTS, path)
        if path.is_symlink() or not _is_model_file(path):
            raise InputError(
                "is not a planeray materials model; planeray never replaces what it did not write: choose "
                "another output or remove it yourself",
                path,
            )


def _is_model_file(path) -> bool:
    """A zip whose record says it is a planeray model (read within the size and depth bounds)."""
    try:
        with zipfile.ZipFile(path) as z:
            info = z.getinfo(_META)
            if info.file_size > MAX_RECORD_BYTES:
                return False
            text = z.read(info)
        if _json_depth(text) > MAX_JSON_DEPTH:
            return False
        meta = json.loads(text)
        return isinstance(meta, dict) and meta.get("format") == MODEL_FORMAT
    except (OSError, zipfile.BadZipFile, KeyError, ValueError, RecursionError):
        return False


def _json_depth(data: bytes) -> int:
    """Deepest nesting of ``[`` and ``{`` in a JSON text, counted without parsing (strings skipped)."""
    import re

    depth = deepest = 0
    for tok in re.finditer(rb'"(?:[^"\\]|\\.)*"|[\[\]{}]', data):
        t = tok.group()
        if t in (b"[", b"{"):
            depth += 1
            deepest = max(deepest, depth)
        elif t in (b"]", b"}"):
            depth -= 1
    return deepest


def _skops_types(blob: bytes, *, path=None) -> set[str]:
    """Every ``module.Class`` named in a skops file's schema (its size and depth bounded first)."""
    with zipfile.ZipFile(io.BytesIO(blob)) as z:
        info = z.getinfo("schema.json")
        if info.file_size > MAX_ESTIMATOR_BYTES:
            raise InputError(f"the estimator's schema is {info.file_size} bytes: too large to be a model", path)
        text = z.read(info)
    depth = _json_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise InputError(
            f"the estimator's schema is nested {depth} deep (a model's: < {MAX_JSON_DEPTH}): not a planeray model",
            path,
        )
    schema = json.loads(text)
    found = set()
    stack = [schema]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            if "__class__" in node:
                found.add(f"{node.get('__module__')}.{node['__class__']}")
            stack.extend(node.values())
        elif isinstance(node, list):
            stack.extend(node)
    return found


def _read_member(z: zipfile.ZipFile, name: str, limit: int, path) -> bytes:
    """A zip member, refused by its recorded size before a byte of it is read."""
    infos = [i for i in z.infolist() if i.filename == name]
    if len(infos) != 1:
        raise InputError(f"is not a planeray materials model ({name} appears {len(infos)} times)", path)
    size = infos[0].file_size
    if size > limit:
        raise InputError(
            f"is not a planeray materials model: its {name} is {size / 2**20:.0f} MiB (at most {limit / 2**20:.0f} MiB)",
            path,
        )
    return z.read(infos[0])


def load_model(path) -> MaterialModel:
    """Load a model saved by :meth:`MaterialModel.save`, refusing anything else.

    Raises :class:`~planeray.errors.InputError` (one line) for a file that is not a
    planeray model, a member larger than :data:`MAX_RECORD_BYTES` /
    :data:`MAX_ESTIMATOR_BYTES` (refused from the zip's directory, before reading it),
    JSON nested deeper than :data:`MAX_JSON_DEPTH`, a ``format_version`` that is not an
    integer, older (a record not covered by its digest) or newer than this planeray
    reads, a record or an estimator whose bytes do not match their recorded SHA-256 (a
    damaged or altered file), one containing a type outside :data:`ALLOWED_TYPES`, or a
    record inconsistent with its estimator (feature count, classes).

    Parameters
    ----------
    path : str or path
        A ``.zip`` written by :meth:`MaterialModel.save`.

    Returns
    -------
    MaterialModel

    See Also
    --------
    MaterialModel.save : writes one.
    train_model : trains one.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> scene = pr.make_scene("wax", (8, 8), seed=0)  # a wax object (label 2) on a plane (label 1)
    >>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
    >>> from planeray.materials import train_model
    >>> model = train_model(
    ...     [stack],
    ...     [scene.labels],
    ...     class_names={1: "plane", 2: "wax"},
    ...     param_grid={"C": (10.0,), "gamma_scale": (1.0,)},
    ...     cv_folds=2,
    ... )
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = model.save(pathlib.Path(tmp) / "model.zip")
    ...     back = load_model(path)
    >>> back.classes == model.classes, bool((back.predict(stack) == model.predict(stack)).all())
    (True, True)
    """
    import skops.io as sio
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVC

    path = Path(path)
    if not path.is_file():
        raise InputError("no such model file", path)
    try:
        with zipfile.ZipFile(path) as z:
            names = [i.filename for i in z.infolist()]
            if _META not in names or _BLOB not in names:
                raise InputError(f"is not a planeray materials model (no {_META} and {_BLOB} inside)", path)
            extra = sorted(set(names) - {_META, _BLOB})
            if extra:
                raise InputError(f"is not a planeray materials model (an extra member {extra[0]!r})", path)
            text = _read_member(z, _META, MAX_RECORD_BYTES, path)
            depth = _json_depth(text)
            if depth > MAX_JSON_DEPTH:
                raise InputError(f"is not a planeray materials model ({_META} is nested {depth} deep)", path)
            meta = json.loads(text)
            _check_record_header(meta, path)
            blob = _read_member(z, _BLOB, MAX_ESTIMATOR_BYTES, path)
    except zipfile.BadZipFile as exc:
        raise InputError(f"is not a planeray materials model (not a zip archive: {exc})", path) from None
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"is not a planeray materials model (unreadable {_META}: {exc})", path) from None
    except OSError as exc:
        raise InputError(f"cannot read the model ({exc.strerror or exc})", path) from None
    if hashlib.sha256(blob).hexdigest() != meta.get("estimator_sha256"):
        raise InputError("the estimator does not match its recorded SHA-256: the file is damaged or was altered", path)
    try:
        types = _skops_types(blob, path=path)
    except (zipfile.BadZipFile, KeyError, ValueError, UnicodeDecodeError, RecursionError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"the estimator is not a skops file ({exc})", path) from None
    untrusted = sorted(types - set(ALLOWED_TYPES))
    if untrusted:
        raise InputError(f"the estimator contains types planeray does not load: {', '.join(untrusted)}", path)
    try:
        pipeline = sio.loads(blob, trusted=[t for t in ALLOWED_TYPES if not t.startswith(("builtins.", "numpy."))])
    except Exception as exc:  # skops raises many types for a malformed file
        raise InputError(f"the estimator cannot be loaded ({type(exc).__name__}: {exc})", path) from None
    steps = getattr(pipeline, "steps", None)
    if (
        not isinstance(pipeline, Pipeline)
        or len(steps) != 2
        or not isinstance(steps[0][1], StandardScaler)
        or not isinstance(steps[1][1], SVC)
    ):
        raise InputError("the estimator is not a StandardScaler + SVC pipeline", path)
    try:
        definition = FeatureDefinition.from_dict(meta["definition"])
        classes = {int(k): str(v) for k, v in meta["classes"].items()}
        typicality = _check_typicality(meta.get("typicality"), definition.n_features, classes)
    except (KeyError, TypeError, ValueError, AttributeError, InputError) as exc:
        raise InputError(f"malformed model record ({exc})", path) from None
    fitted = np.asarray(getattr(steps[1][1], "classes_", []))
    if sorted(classes) != sorted(int(c) for c in fitted.tolist()):
        raise InputError(
            f"malformed model record (classes {sorted(classes)}; the estimator predicts {fitted.tolist()})", path
        )
    n_in = getattr(steps[0][1], "n_features_in_", None)
    if n_in != definition.n_features:
        raise InputError(f"malformed model record ({definition.n_features} features; the estimator takes {n_in})", path)
    return MaterialModel(pipeline, definition, classes, meta.get("training", {}), typicality)


def _check_record_header(meta, path) -> None:
    """Format, version and the record's own digest, checked before the estimator is read."""
    if not isinstance(meta, dict) or meta.get("format") != MODEL_FORMAT:
        found = meta.get("format") if isinstance(meta, dict) else None
        raise InputError(f"is not a planeray materials model (format {found!r})", path)
    version = meta.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int):
        raise InputError(f"malformed model record (format_version must be an integer, got {version!r})", path)
    if version > MODEL_FORMAT_VERSION:
        raise InputError(
            f"model format version {version} is newer than this planeray reads ({MODEL_FORMAT_VERSION})", path
        )
    if version < MODEL_FORMAT_VERSION:
        raise InputError(
            f"model format version {version} was written by an earlier planeray, its record not covered by a "
            "digest: train the model again with this planeray",
            path,
        )
    try:
        digest = record_digest(meta)
    except ValueError:
        digest = None
    if digest is None or meta.get("record_sha256") != digest:
        raise InputError(
            "the model record does not match its recorded SHA-256 (record_sha256): the file is damaged or was altered",
            path,
        )


def _check_typicality(data, n_features: int, classes: dict) -> dict:
    """The typicality model of a record, its shapes and numbers checked (``{}``: none)."""
    if not data:
        return {}
    comp = np.asarray(data["components"], dtype=np.float64)
    mean = np.asarray(data["mean"], dtype=np.float64)
    if comp.ndim != 2 or comp.shape[1] != n_features or mean.shape != (n_features,):
        raise ValueError(f"typicality components {comp.shape} do not match {n_features} features")
    k = comp.shape[0] + 1
    area_center, area_scale = float(data["area_center"]), float(data["area_scale"])
    if not (np.isfinite(area_center) and np.isfinite(area_scale) and area_scale > 0):
        raise ValueError("typicality area_center and area_scale must be finite, the scale > 0")
    out = {"area_center": area_center, "area_scale": area_scale, "classes": {}}
    for cid, entry in data["classes"].items():
        if int(cid) not in classes:
            raise ValueError(f"typicality of class {cid}, which the model does not predict")
        center = np.asarray(entry["center"], dtype=np.float64)
        prec = np.asarray(entry["precision"], dtype=np.float64)
        cal = np.asarray(entry["calibration"], dtype=np.float64)
        if center.shape != (k,) or prec.shape != (k, k) or cal.ndim != 1:
            raise ValueError(f"typicality of class {cid} has the wrong shapes")
        if not (np.all(np.isfinite(center)) and np.all(np.isfinite(prec)) and np.all(np.isfinite(cal))):
            raise ValueError(f"typicality of class {cid} is not finite")
        if np.any(np.diff(cal) < 0):
            raise ValueError(f"typicality calibration of class {cid} is not sorted")
        out["classes"][str(int(cid))] = {"center": center, "precision": prec, "calibration": cal}
    if set(out["classes"]) != {str(c) for c in classes}:
        raise ValueError(f"typicality of classes {sorted(out['classes'])}, the model predicts {sorted(classes)}")
    if not np.all(np.isfinite(comp)) or not np.all(np.isfinite(mean)):
        raise ValueError("typicality components are not finite")
    out["components"], out["mean"] = comp, mean
    return out
