"""Training the material classifier: an RBF support vector machine on delay profiles (Sec. 8, Fig. 10c, d).

:func:`train_model` (the method in :mod:`planeray.materials.model`'s docstring): scaler and
``SVC(kernel="rbf")``, ``C`` and ``gamma`` by cross-validation grouped by capture, and the
typicality model of each class (:func:`fit_typicality`).
"""

from __future__ import annotations

import numpy as np

from .._validate import check_integer
from ..errors import InputError
from ..optical_data import CLASS_NAMES, UNLABELLED
from .capture import capture_features
from .features import FEATURE_KINDS, FLOORS
from .model_format import (
    TYPICALITY_COMPONENTS,
    MaterialModel,
    _mahalanobis2,
    _typicality_space,
)

#: Hyper-parameters searched: ``C`` and ``gamma`` (``gamma`` relative to 1 / n_features,
#: scikit-learn's ``"scale"`` for standardized features).
DEFAULT_PARAM_GRID = {"C": (1.0, 10.0, 100.0, 1000.0), "gamma_scale": (0.1, 0.3, 1.0, 3.0)}


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
        Called as ``progress(done, total, stage)``: after each capture's features
        (``stage`` ``"features"``, ``total`` the captures), then before and after each
        fit of the cross-validation, the final fit and the typicality model
        (``"cross-validation"``, ``total`` the fits).

    Returns
    -------
    MaterialModel

    See Also
    --------
    MaterialModel : the model.
    load_model : a saved model.

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
    >>> sorted(model.classes.values())
    ['plane', 'wax']
    """
    from sklearn.model_selection import GridSearchCV, GroupKFold
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVC

    stacks, labels = list(stacks), list(labels)
    check_training_options(
        kind=kind,
        floor=floor,
        class_names=class_names,
        ignore_classes=ignore_classes,
        max_per_class=max_per_class,
        cv_folds=cv_folds,
        seed=seed,
    )
    if not stacks:
        raise InputError("give at least one training capture")
    if len(labels) != len(stacks):
        raise InputError(f"{len(stacks)} stacks but {len(labels)} label images: give one label image per stack")
    sources = list(sources) if sources is not None else [f"capture {i}" for i in range(len(stacks))]
    transports = list(transports) if transports is not None else [None] * len(stacks)
    rng = np.random.default_rng(seed)
    X_all, y_all, g_all, a_all, definition = [], [], [], [], None
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
        a_all.append(signal.ravel()[keep])
        if progress is not None:
            progress(i + 1, len(stacks), "features")
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
    fits = [0, len(grid["C"]) * len(grid["gamma_scale"]) * folds + 2]  # the grid, the final fit, the typicality

    def tick(step=1):
        fits[0] += step
        if progress is not None:
            progress(fits[0], fits[1], "cross-validation")

    def scorer(estimator, X_val, y_val):  # the grid search's score, and a tick per fit
        tick()
        return float(np.mean(estimator.predict(X_val) == y_val))

    tick(0)
    search = GridSearchCV(
        Pipeline([("scale", StandardScaler()), ("svc", SVC(kernel="rbf", class_weight="balanced"))]),
        {"svc__C": [float(c) for c in grid["C"]], "svc__gamma": [float(s) / nf for s in grid["gamma_scale"]]},
        cv=GroupKFold(n_splits=folds),
        scoring=scorer,
        refit=True,
        n_jobs=1,
    )
    search.fit(X, y, groups=groups)
    fits[0] = fits[1] - 2  # (a fit that failed is not scored)
    tick()  # the final fit
    typicality = fit_typicality(search.best_estimator_.steps[0][1].transform(X), y, groups, np.concatenate(a_all))
    tick()
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
    return MaterialModel(search.best_estimator_, definition, classes, training, typicality)


def check_training_options(
    *, kind="stack", floor="edge", class_names=None, ignore_classes=(), max_per_class=400, cv_folds=4, seed=0
) -> None:
    """Refuse training options that cannot work, before any capture is read (names as :func:`train_model`'s)."""
    if kind not in FEATURE_KINDS:
        raise InputError(f"kind must be one of {', '.join(FEATURE_KINDS)}, got {kind!r}")
    if floor not in FLOORS:
        raise InputError(f"floor must be one of {', '.join(FLOORS)}, got {floor!r}")
    check_integer(max_per_class, "max_per_class", minimum=10, maximum=MAX_PER_CLASS)
    check_integer(cv_folds, "cv_folds", minimum=2, maximum=20)
    check_integer(seed, "seed", minimum=0, maximum=2**32 - 1)
    for c in ignore_classes or ():
        check_integer(c, "ignore_class", minimum=1, maximum=255)
    for cid, name in (class_names or {}).items():
        check_integer(cid, "class_name", minimum=1, maximum=255)
        if not str(name).strip():
            raise InputError(f"class_name must give class {cid} a name, got {name!r}")


#: Most training pixels per class and capture: the SVM's cost grows with the square of the pixel count.
MAX_PER_CLASS = 5000


def fit_typicality(Z, y, groups, area, *, n_components: int = TYPICALITY_COMPONENTS) -> dict:
    """The typicality model of standardized training features ``Z`` and their profiles' ``area`` (module docstring).

    Principal components of ``Z`` and the standardized log area; per class a Ledoit-Wolf
    Gaussian of its pixels in them, and the calibration: the squared Mahalanobis distance of each of its pixels
    under a fit to the class's pixels of the *other* groups (captures or image blocks;
    a class found in one group only: five random folds of it), sorted.
    """
    from sklearn.covariance import LedoitWolf
    from sklearn.decomposition import PCA

    Z = np.asarray(Z, dtype=np.float64)
    k = int(min(n_components, Z.shape[1], max(Z.shape[0] - 1, 1)))
    pca = PCA(n_components=k, svd_solver="full").fit(Z)
    log_area = np.log(np.maximum(np.asarray(area, dtype=np.float64), 1e-300))
    model = {
        "components": pca.components_,
        "mean": pca.mean_,
        "area_center": float(np.mean(log_area)),
        "area_scale": float(np.std(log_area)) or 1.0,
    }
    P = _typicality_space(model, Z, area)
    rng = np.random.default_rng(0)
    classes = {}
    for c in np.unique(y):
        Pc, gc = P[y == c], np.asarray(groups)[y == c]
        if np.unique(gc).size < 2:  # one group: five random folds of it
            gc = rng.permutation(np.arange(gc.size) % 5)
        scores = []
        for g in np.unique(gc):
            held = gc == g
            if (~held).sum() > k + 1:
                fit = LedoitWolf().fit(Pc[~held])
                scores.append(_mahalanobis2(Pc[held], fit.location_, fit.precision_))
        whole = LedoitWolf().fit(Pc)
        classes[str(int(c))] = {
            "center": whole.location_,
            "precision": whole.precision_,
            "calibration": np.sort(np.concatenate(scores)) if scores else np.zeros(0),
        }
    return {**model, "classes": classes}
