"""Recognizing subsurface-scattering materials from their delay profiles (Sec. 8, Fig. 10).

* :mod:`planeray.materials.features`: per-pixel area-normalized delay profiles of a stack
  or of its demultiplexed transport, and the definition a model keeps of them;
* :mod:`planeray.materials.model`: the RBF-SVM classifier (scikit-learn), trained with
  cross-validation grouped by capture, saved without pickle (skops + JSON);
* :mod:`planeray.materials.labels`: label images (class ids as PNG/TIFF);
* the media and the documented class list come from :mod:`planeray.optical_data`
  (re-exported here), the scene from :mod:`planeray.scenes.materials` and the whole
  experiment from :mod:`planeray.experiments.materials`.
"""

from ..optical_data import (
    BACKGROUND_CLASS,
    CLASS_NAMES,
    MATERIAL_CLASSES,
    UNLABELLED,
    material_media,
    material_medium,
    optical_table,
)
from .features import FeatureDefinition, normalize_profiles, remove_floor, stack_features, transport_features
from .labels import read_label_image, write_label_image
from .model import ALLOWED_TYPES, MaterialModel, capture_features, capture_transport, load_model, train_model

__all__ = [
    "ALLOWED_TYPES",
    "BACKGROUND_CLASS",
    "CLASS_NAMES",
    "FeatureDefinition",
    "MATERIAL_CLASSES",
    "MaterialModel",
    "UNLABELLED",
    "capture_features",
    "capture_transport",
    "load_model",
    "material_media",
    "material_medium",
    "normalize_profiles",
    "optical_table",
    "read_label_image",
    "remove_floor",
    "stack_features",
    "train_model",
    "transport_features",
    "write_label_image",
]
