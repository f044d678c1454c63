"""End-to-end experiments: each one simulates (or reads) captures, analyses them and writes its numbers
(JSON/CSV) and figures (PNG) into a folder.

* :mod:`planeray.experiments.paper`: the paper's figures reproduced on the simulated device
  (``planeray figure ...``);
* :mod:`planeray.experiments.study`: the Sec. 5.2 demultiplexing study (``planeray study demux``);
* :mod:`planeray.experiments.reproduce`: every figure at once, resumable (``planeray paper``), and
  :mod:`planeray.experiments.paper_report`, its report beside the paper's quoted numbers.

* the commands' documented outputs as functions (each command's whole work; the command line
  parses its options, calls one of them and prints):
  :mod:`planeray.experiments.materials_folders` (``materials fit``),
  :mod:`planeray.experiments.materials_recognize` (``materials recognize``, ``library-add``,
  ``predict``), :mod:`planeray.experiments.skin_folders` (``skin veins``, ``enhance``),
  :mod:`planeray.experiments.skin_depth_folder` (``skin depth``),
  :mod:`planeray.experiments.simulate` (``simulate``) and :mod:`planeray.experiments.baselines`
  (``separate direct-global``, ``emulate``).  They live here, not in the domain
  packages, because their folders hold figures: ``experiments`` is the lowest layer that may
  draw them.

Experiments sit above analysis and figures: they compose them, nothing below imports them.
"""
