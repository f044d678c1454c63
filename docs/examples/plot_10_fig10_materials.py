"""
Fig. 10: recognizing materials from their delay profiles
========================================================

Five white scattering media (milks, toothpaste, soap) look alike in a photo but scatter light
over different distances under the surface, so their area-normalized delay profiles differ
(Sec. 8). An RBF support-vector machine trained on the profiles of one labelled capture
segments another one, taken at another place with more noise and ambient light (paper Fig. 10;
here at 64x64).

Command line: ``planeray materials simulate``, ``materials train``, ``materials predict``;
``planeray materials report`` runs the whole experiment.
"""

import numpy as np

from planeray.experiments.materials import simulate_capture
from planeray.figures.materials import materials_photo_figure, segmentation_figure
from planeray.materials import train_model

train = simulate_capture(size=(64, 64), seed=0, placement=0, noise=1.0, ambient_e_per_us=0.5)
test = simulate_capture(size=(64, 64), seed=1, placement=1, noise=1.5, ambient_e_per_us=1.5)
fig = materials_photo_figure(train.photo, train.labels)

# %%
# Train on the five materials (class 6, the table, is left out as in the paper's Fig. 10d) and
# predict every pixel of the held-out capture.

model = train_model([train.stack], [train.labels], ignore_classes=(6,), max_per_class=200, cv_folds=3)
pred = model.predict(test.stack, unclassified_below=0.0)
scored = (test.labels > 0) & (test.labels != 6)
accuracy = float(np.mean(pred[scored] == test.labels[scored]))
print(f"per-pixel accuracy on the held-out capture: {100 * accuracy:.1f} %")
fig = segmentation_figure(test.labels, pred, near_wall=test.near_wall, scored=scored)
