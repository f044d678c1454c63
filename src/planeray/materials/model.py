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
feature definition, class names, training record, typicality model, SHA-256 of the
estimator, and a SHA-256 of the whole record itself) and ``model.skops``, the estimator
in the skops format, loaded only if every type in it is on the explicit list
:data:`ALLOWED_TYPES`.  :func:`load_model` bounds everything before reading it: the
members' sizes (:data:`MAX_RECORD_BYTES`, :data:`MAX_ESTIMATOR_BYTES`, from the zip's
directory) and the nesting depth of both JSON documents (:data:`MAX_JSON_DEPTH`).

**Unclassified pixels.**  An SVM assigns every pixel to one of the classes it was
trained on, however unlike them the pixel is (a table left out of training becomes
"toothpaste").  :meth:`MaterialModel.segment` therefore also asks how *typical* a pixel
is of the class the SVM picks: the squared Mahalanobis distance to the class's training
pixels (Ledoit-Wolf covariance) of the pixel's standardized features in the 6 leading
principal components of the training features, and of its brightness (the log of the
area of its profiles before normalization, standardized), turned into a conformal p-value
against the same distance of held-out training pixels of that class (each scored by a
fit to the *other* captures or image blocks): ``p = (1 + #{held-out >= d}) / (n + 1)``,
the share of the class's held-out pixels at least as unlike it.  A pixel with ``p``
below ``unclassified_below`` (:data:`DEFAULT_UNCLASSIFIED_BELOW`) is *unclassified*
(class id 0).  The profile's shape alone barely tells a matte table from the nearly
opaque toothpaste (measured: 0.3 % of a table left out of training unclassified at the
training conditions); its brightness does (100 %).  So a capture with another laser
power or camera gain than the training captures reads as unlike them: train on it, or
pass ``unclassified_below=0``.
"""

from __future__ import annotations

from .capture import DEFAULT_DEMUX, capture_features, capture_transport
from .model_format import (
    ALLOWED_TYPES,
    DEFAULT_UNCLASSIFIED_BELOW,
    MAX_ESTIMATOR_BYTES,
    MAX_JSON_DEPTH,
    MAX_RECORD_BYTES,
    MODEL_FORMAT,
    MODEL_FORMAT_VERSION,
    TYPICALITY_COMPONENTS,
    MaterialModel,
    Segmentation,
    check_model_output,
    check_unclassified_below,
    load_model,
    record_digest,
)
from .training import DEFAULT_PARAM_GRID, MAX_PER_CLASS, check_training_options, fit_typicality, train_model

#: The public names of the model, its file and its training (defined in the modules above; re-exported here,
#: where the command line and the experiments import them).
__all__ = [
    "MODEL_FORMAT",
    "MODEL_FORMAT_VERSION",
    "ALLOWED_TYPES",
    "DEFAULT_UNCLASSIFIED_BELOW",
    "MAX_ESTIMATOR_BYTES",
    "MAX_JSON_DEPTH",
    "MAX_RECORD_BYTES",
    "TYPICALITY_COMPONENTS",
    "MaterialModel",
    "Segmentation",
    "train_model",
    "load_model",
    "capture_features",
    "capture_transport",
    "DEFAULT_PARAM_GRID",
    "DEFAULT_DEMUX",
    "MAX_PER_CLASS",
    "check_model_output",
    "check_training_options",
    "check_unclassified_below",
    "fit_typicality",
    "record_digest",
]
