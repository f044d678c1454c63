"""Per-pixel material recognition: an RBF support vector machine on delay profiles (Sec. 8, Fig. 10c, d).

Kubo et al. train "a support vector machine (SVM) with nonlinear kernel (radial Gaussian
basis function)" on the delay profiles of training images and apply it per pixel to test
images.  :func:`train_model` does that with scikit-learn: a pipeline of a
:class:`~sklearn.preprocessing.StandardScaler` and ``SVC(kernel="rbf",
class_weight="balanced")``, whose ``C`` and ``gamma`` are chosen by cross-validation
**grouped by capture** (every fold validates on captures it did not train on; with a
single capture, on blocks of the image it did not train on), then refit on all the
training pixels.

A :class:`MaterialModel` keeps the feature definition it was trained on
(:class:`~planeray.materials.features.FeatureDefinition`: delays, exposures,
normalization, floor, lines per second) and refuses data of any other sweep.  It is
saved without pickle: one zip file holding ``planeray-model.json`` (format, version,
feature definition, class names, training record, SHA-256 of the estimator) and
``model.skops``, the estimator in the skops format, loaded only if every type in it is
on the explicit list :data:`ALLOWED_TYPES`.
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import atomic_file
from ..io.atomic import ALREADY_EXISTS
from ..optical_data import CLASS_NAMES, UNLABELLED
from ..stack import Stack
from .features import FEATURE_KINDS, FeatureDefinition, stack_features, transport_features

__all__ = [
    "MODEL_FORMAT",
    "MODEL_FORMAT_VERSION",
    "ALLOWED_TYPES",
    "MaterialModel",
    "train_model",
    "load_model",
    "capture_features",
    "capture_transport",
    "DEFAULT_PARAM_GRID",
]

MODEL_FORMAT = "planeray-materials-model"
MODEL_FORMAT_VERSION = 1
_META = "planeray-model.json"
_BLOB = "model.skops"

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
#: Hyper-parameters searched: ``C`` and ``gamma`` (``gamma`` relative to 1 / n_features,
#: scikit-learn's ``"scale"`` for standardized features).
DEFAULT_PARAM_GRID = {"C": (1.0, 10.0, 100.0, 1000.0), "gamma_scale": (0.1, 0.3, 1.0, 3.0)}


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
    """

    pipeline: object
    definition: FeatureDefinition
    classes: dict
    training: dict = field(default_factory=dict)

    # ------------------------------------------------------------ prediction
    def predict_features(self, features) -> np.ndarray:
        """Class ids of feature rows ``(P, F)``."""
        X = np.asarray(features, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != self.definition.n_features:
            raise InputError(f"expected features of shape (P, {self.definition.n_features}), got {X.shape}")
        return self.pipeline.predict(X).astype(np.int64)

    def predict(self, stack: Stack, *, transport=None, source=None, progress=None) -> np.ndarray:
        """Per-pixel class ids ``(H, W)`` of a stack (0 where a pixel has no usable profile).

        Parameters
        ----------
        stack : Stack
            Captured with the sweep the model was trained on (else :class:`InputError`).
        transport : Transport, optional
            For a transport model: the stack's transport if already demultiplexed with
            the model's options (:func:`capture_transport`); otherwise it is demultiplexed here.
        source : str, optional
            Name of the stack in error messages.
        progress : callable, optional
            Demultiplexing progress (rows).
        """
        X, signal, _ = capture_features(
            stack, definition=self.definition, transport=transport, source=source, progress=progress
        )
        labels = np.zeros(signal.shape, np.int64)
        ok = signal.ravel() > 0
        if ok.any():
            labels.ravel()[ok] = self.predict_features(X[ok])
        return labels

    # ------------------------------------------------------------ storage
    def save(self, path, *, overwrite: bool = False) -> Path:
        """Write the model (zip: JSON record + skops estimator), atomically; no pickle.

        An existing file is replaced only with ``overwrite`` and only if it is a planeray
        model itself.
        """
        import sklearn
        import skops
        import skops.io as sio

        from ..io._common import planeray_version

        path = Path(path)
        if path.exists() or path.is_symlink():
            if not overwrite:
                raise InputError(ALREADY_EXISTS, path)
            if path.is_symlink() or not _is_model_file(path):
                raise InputError(
                    "is not a planeray materials model; planeray never replaces what it did not write: choose "
                    "another output or remove it yourself",
                    path,
                )
        blob = sio.dumps(self.pipeline)
        meta = {
            "format": MODEL_FORMAT,
            "format_version": MODEL_FORMAT_VERSION,
            "definition": self.definition.to_dict(),
            "classes": {str(k): v for k, v in self.classes.items()},
            "training": self.training,
            "estimator_sha256": hashlib.sha256(blob).hexdigest(),
            "planeray_version": planeray_version(),
            "sklearn_version": sklearn.__version__,
            "skops_version": skops.__version__,
        }
        with atomic_file(path, overwrite=True) as tmp:
            with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as z:
                z.writestr(_META, json.dumps(meta, indent=1, sort_keys=True))
                z.writestr(_BLOB, blob)
        return path


def _is_model_file(path) -> bool:
    try:
        with zipfile.ZipFile(path) as z:
            return json.loads(z.read(_META)).get("format") == MODEL_FORMAT
    except (OSError, zipfile.BadZipFile, KeyError, ValueError, AttributeError):
        return False


def _skops_types(blob: bytes) -> set[str]:
    """Every ``module.Class`` named in a skops file's schema."""
    with zipfile.ZipFile(io.BytesIO(blob)) as z:
        schema = json.loads(z.read("schema.json"))
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


def load_model(path) -> MaterialModel:
    """Load a model saved by :meth:`MaterialModel.save`, refusing anything else.

    Raises :class:`~planeray.errors.InputError` (one line) for a file that is not a
    planeray model, a newer format, an estimator whose bytes do not match the recorded
    SHA-256 (a damaged or altered file), or one containing a type outside
    :data:`ALLOWED_TYPES`.
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
            names = set(z.namelist())
            if _META not in names or _BLOB not in names:
                raise InputError(f"is not a planeray materials model (no {_META} and {_BLOB} inside)", path)
            meta = json.loads(z.read(_META))
            blob = z.read(_BLOB)
    except zipfile.BadZipFile:
        raise InputError("is not a planeray materials model (not a zip archive)", path) from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"is not a planeray materials model (unreadable {_META}: {exc})", path) from None
    if not isinstance(meta, dict) or meta.get("format") != MODEL_FORMAT:
        raise InputError(
            f"is not a planeray materials model (format {meta.get('format') if isinstance(meta, dict) else None!r})",
            path,
        )
    if int(meta.get("format_version", 0)) > MODEL_FORMAT_VERSION:
        raise InputError(
            f"model format version {meta.get('format_version')} is newer than this planeray reads ({MODEL_FORMAT_VERSION})",
            path,
        )
    if hashlib.sha256(blob).hexdigest() != meta.get("estimator_sha256"):
        raise InputError("the estimator does not match its recorded SHA-256: the file is damaged or was altered", path)
    try:
        types = _skops_types(blob)
    except (zipfile.BadZipFile, KeyError, ValueError) as exc:
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
    except (KeyError, TypeError, ValueError, InputError) as exc:
        raise InputError(f"malformed model record ({exc})", path) from None
    return MaterialModel(pipeline, definition, classes, meta.get("training", {}))


# ---------------------------------------------------------------- features of a capture
def capture_features(
    stack: Stack,
    *,
    kind: str = "stack",
    floor: str = "edge",
    definition: FeatureDefinition | None = None,
    transport=None,
    demux: dict | None = None,
    source=None,
    progress=None,
):
    """Features of every pixel of a capture: measured profiles, or those of its demultiplexed transport.

    ``definition`` (a model's) fixes the kind, floor and demultiplexing; otherwise
    ``kind``, ``floor`` and ``demux`` (``alpha``, ``beta``, ``method``; default the
    paper's 0.01, 0.01, ``"fast"``) do.  A transport, if not given, is
    :func:`capture_transport` of the stack.  Returns ``(features, signal, definition)``.
    """
    if definition is not None:
        kind = definition.kind
    if kind not in FEATURE_KINDS:
        raise InputError(f"unknown feature kind {kind!r}; choose one of {', '.join(FEATURE_KINDS)}")
    if kind == "stack":
        return stack_features(stack, floor=floor, definition=definition, source=source)
    opts = (
        dict(definition.demux)
        if definition is not None
        else {"alpha": 0.01, "beta": 0.01, "method": "fast", **(demux or {})}
    )
    if transport is None:
        from ..demux import demultiplex

        transport = demultiplex(
            stack, alpha=opts["alpha"], beta=opts["beta"], method=opts["method"], progress=progress
        ).transport
    return transport_features(
        transport,
        lines_per_second=stack.lines_per_second,
        floor=floor if definition is None else definition.floor,
        demux=opts,
        definition=definition,
        source=source,
    )


#: Demultiplexing options of transport features (the paper's weights, the fast solver).
DEFAULT_DEMUX = {"alpha": 0.01, "beta": 0.01, "method": "fast"}


def capture_transport(stack: Stack, *, floor: str = "edge", demux: dict | None = None, progress=None):
    """The transport of a capture as transport features see it: floor removed, then demultiplexed.

    :func:`~planeray.materials.features.remove_floor` then :func:`planeray.demux.demultiplex`
    with ``demux`` (default :data:`DEFAULT_DEMUX`).
    """
    from ..demux import demultiplex
    from .features import remove_floor

    opts = {**DEFAULT_DEMUX, **(demux or {})}
    return demultiplex(
        remove_floor(stack, floor=floor),
        alpha=opts["alpha"],
        beta=opts["beta"],
        method=opts["method"],
        progress=progress,
    ).transport


# ---------------------------------------------------------------- training
def _sample(y, max_per_class, rng):
    """Indices of labelled pixels of one capture: at most ``max_per_class`` per class, drawn at random."""
    keep = []
    for c in np.unique(y):
        if c == UNLABELLED:
            continue
        idx = np.flatnonzero(y == c)
        if idx.size > max_per_class:
            idx = rng.choice(idx, max_per_class, replace=False)
        keep.append(idx)
    return np.sort(np.concatenate(keep)) if keep else np.zeros(0, np.int64)


def train_model(
    stacks,
    labels,
    *,
    kind: str = "stack",
    floor: str = "edge",
    demux: dict | None = None,
    class_names: dict | None = None,
    ignore_classes=(),
    max_per_class: int = 400,
    cv_folds: int = 4,
    param_grid: dict | None = None,
    seed: int = 0,
    sources=None,
    transports=None,
    progress=None,
) -> MaterialModel:
    """Train the per-pixel RBF-SVM classifier on labelled captures.

    Parameters
    ----------
    stacks : sequence of Stack
        Training captures, all of the same sweep.
    labels : sequence of ndarray (H, W) int
        Class ids per pixel (0: unlabelled, left out), one image per stack.
    kind : {"stack", "transport"}
        Measured profiles or demultiplexed transport profiles
        (:mod:`planeray.materials.features`).
    floor : {"edge", "min", "none"}
        Floor removal before the area normalization (:mod:`planeray.materials.features`).
    demux : dict, optional
        Demultiplexing options of a transport model.
    class_names : dict, optional
        Names of class ids; default the documented list
        (:data:`planeray.optical_data.CLASS_NAMES`), ``"class N"`` for others.
    ignore_classes : sequence of int
        Class ids treated as unlabelled (e.g. the background, 6: the paper recognizes the
        five materials only, and a nearly opaque paste and a matte table have nearly the
        same profile).
    max_per_class : int
        Training pixels per class and capture (drawn at random): the SVM's cost grows
        with the square of the pixel count.
    cv_folds : int
        Folds of the grouped cross-validation.
    param_grid : dict, optional
        ``{"C": [...], "gamma_scale": [...]}`` (``gamma = gamma_scale / n_features``);
        default :data:`DEFAULT_PARAM_GRID`.
    seed : int
        Seed of the pixel sampling.
    sources : sequence of str, optional
        Names of the stacks (error messages, training record).
    transports : sequence of Transport, optional
        The stacks' transports, if already computed by :func:`capture_transport` with
        the same floor and options (transport models).
    progress : callable, optional
        Called with 1 after each capture's features.

    Returns
    -------
    MaterialModel
    """
    from sklearn.model_selection import GridSearchCV, GroupKFold
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVC

    stacks, labels = list(stacks), list(labels)
    if not stacks:
        raise InputError("give at least one training capture")
    if len(labels) != len(stacks):
        raise InputError(f"{len(stacks)} stacks but {len(labels)} label images: give one label image per stack")
    sources = list(sources) if sources is not None else [f"capture {i}" for i in range(len(stacks))]
    transports = list(transports) if transports is not None else [None] * len(stacks)
    rng = np.random.default_rng(seed)
    X_all, y_all, g_all, definition = [], [], [], None
    for i, (st, lab) in enumerate(zip(stacks, labels)):
        lab = np.asarray(lab)
        if lab.shape != st.shape:
            raise InputError(
                f"label image is {lab.shape[0]}x{lab.shape[1]}, the stack {st.shape[0]}x{st.shape[1]}", sources[i]
            )
        X, signal, d = capture_features(
            st, kind=kind, floor=floor, demux=demux, definition=definition, transport=transports[i], source=sources[i]
        )
        definition = definition or d
        y = lab.ravel().astype(np.int64)
        y = np.where(signal.ravel() > 0, y, UNLABELLED)  # no profile, nothing to learn
        y = np.where(np.isin(y, list(ignore_classes)), UNLABELLED, y)
        if len(stacks) > 1:
            groups = np.full(y.size, i)
        else:  # one capture: blocks of the image (4 x 4), so no fold validates beside its training pixels
            H, W = st.shape
            r, c = np.divmod(np.arange(y.size), W)
            groups = (r * 4 // H) * 4 + (c * 4 // W)
        keep = _sample(y, max_per_class, rng)
        X_all.append(X[keep])
        y_all.append(y[keep])
        g_all.append(groups[keep])
        if progress is not None:
            progress(1)
    X, y, groups = np.concatenate(X_all).astype(np.float64), np.concatenate(y_all), np.concatenate(g_all)
    present = np.unique(y)
    if present.size < 2:
        raise InputError(f"the label images hold {present.size} class(es); training needs at least two")
    n_groups = np.unique(groups).size
    folds = min(int(cv_folds), n_groups)
    if folds < 2:
        raise InputError("cross-validation needs at least two groups (captures or image blocks)")
    grid = dict(DEFAULT_PARAM_GRID if param_grid is None else param_grid)
    nf = X.shape[1]
    search = GridSearchCV(
        Pipeline([("scale", StandardScaler()), ("svc", SVC(kernel="rbf", class_weight="balanced"))]),
        {"svc__C": [float(c) for c in grid["C"]], "svc__gamma": [float(s) / nf for s in grid["gamma_scale"]]},
        cv=GroupKFold(n_splits=folds),
        scoring="accuracy",
        refit=True,
        n_jobs=1,
    )
    search.fit(X, y, groups=groups)
    names = {**CLASS_NAMES, **({int(k): str(v) for k, v in class_names.items()} if class_names else {})}
    classes = {int(c): names.get(int(c), f"class {int(c)}") for c in present}
    cv = search.cv_results_
    training = {
        "captures": [str(s) for s in sources],
        "pixels_per_class": {str(int(c)): int((y == c).sum()) for c in present},
        "groups": "captures" if len(stacks) > 1 else "4x4 image blocks",
        "cv_folds": folds,
        "best": {"C": search.best_params_["svc__C"], "gamma": search.best_params_["svc__gamma"]},
        "cv_accuracy": float(search.best_score_),
        "grid": [
            {"C": float(p["svc__C"]), "gamma": float(p["svc__gamma"]), "accuracy": float(m)}
            for p, m in zip(cv["params"], cv["mean_test_score"])
        ],
        "seed": int(seed),
        "max_per_class": int(max_per_class),
        "ignored_classes": sorted(int(c) for c in ignore_classes),
    }
    return MaterialModel(search.best_estimator_, definition, classes, training)
